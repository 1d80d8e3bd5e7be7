#!/usr/bin/env bash
# Configures and builds tetstream.
# Usage: scripts/build.sh [BUILD_DIR] [--targets-only-concurrency] [extra cmake args...]
#   --targets-only-concurrency builds only the test binaries labelled `concurrency`
#   (tests/CMakeLists.txt: TETSTREAM_CONCURRENCY_TESTS), for the ThreadSanitizer tier.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${1:-$root/build}
shift || true
targets=()
if [ "${1:-}" = "--targets-only-concurrency" ]; then
  shift
  targets=(--target tetstream_concurrency_tests)
fi
generator=()
command -v ninja >/dev/null && generator=(-G Ninja)
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
if [ ! -f "$build/CMakeCache.txt" ]; then
  cmake -S "$root" -B "$build" "${generator[@]}" "${launcher[@]}" -DCMAKE_BUILD_TYPE=Release "$@"
elif (($# > 0)); then
  cmake "$build" "$@" >/dev/null
fi
cmake --build "$build" -j "$(nproc)" "${targets[@]}"
