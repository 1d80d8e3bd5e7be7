#!/usr/bin/env bash
# Sets up, builds and runs the whole test suite: unit, CGAL comparison, CLI and Python
# reader tests in Release, then the unit tests again under ASan/UBSan.
# Usage: scripts/test.sh            (everything)
#        scripts/test.sh --no-sanitize
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
sanitize=1
[ "${1:-}" = "--no-sanitize" ] && sanitize=0

"$root/scripts/setup.sh"
jobs=$(nproc)

echo "== Release build and full suite"
"$root/scripts/build.sh" "$root/build"
# setup.sh installed OpenMPI: the mpirun tests must run, not skip.
export TETSTREAM_REQUIRE_MPI=1
ctest --test-dir "$root/build" --output-on-failure -j "$jobs" --timeout 900

if ((sanitize)); then
  echo "== ASan/UBSan build and unit tests"
  "$root/scripts/build.sh" "$root/build-asan" -DTETSTREAM_SANITIZE=ON -DTETSTREAM_CGAL_TESTS=OFF \
    -DCMAKE_BUILD_TYPE=RelWithDebInfo
  ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
    ctest --test-dir "$root/build-asan" --output-on-failure -j "$jobs" -L unit --timeout 900
fi
