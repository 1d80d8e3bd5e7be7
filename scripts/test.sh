#!/usr/bin/env bash
# Sets up, builds and runs the whole test suite (docs/testing.md): the lint checks, every
# test in Release with warnings as errors, then the unit tests under ASan/UBSan and the
# concurrency tests under ThreadSanitizer.
# Usage: scripts/test.sh                 (everything)
#        scripts/test.sh --no-sanitize   (the Release suite only)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
sanitize=1
[ "${1:-}" = "--no-sanitize" ] && sanitize=0

"$root/scripts/setup.sh"
jobs=$(nproc)

# Warnings are errors in the Release build, the one every user compiles; the sanitizer
# builds keep them as warnings (GCC's instrumented code raises spurious ones).
echo "== Release build (warnings are errors) and full suite"
"$root/scripts/build.sh" "$root/build" -DTETSTREAM_WERROR=ON
# setup.sh installed OpenMPI: the mpirun tests must run, not skip.
export TETSTREAM_REQUIRE_MPI=1
ctest --test-dir "$root/build" --output-on-failure -j "$jobs" --timeout 900

if ((sanitize)); then
  echo "== ASan/UBSan build and the unit tests (the quick tier and the pipeline unit tests)"
  "$root/scripts/build.sh" "$root/build-asan" -DTETSTREAM_SANITIZE=ON -DTETSTREAM_CGAL_TESTS=OFF \
    -DCMAKE_BUILD_TYPE=RelWithDebInfo
  ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
    ctest --test-dir "$root/build-asan" --output-on-failure -j "$jobs" -L unit --timeout 900

  echo "== ThreadSanitizer build and the concurrency tests"
  "$root/scripts/build.sh" "$root/build-tsan" --targets-only-concurrency -DTETSTREAM_TSAN=ON \
    -DTETSTREAM_CGAL_TESTS=OFF -DCMAKE_BUILD_TYPE=RelWithDebInfo
  # OpenMP regions on one thread (tests/tsan.supp says why): the project's own threads
  # (the writer's, the queues, ranks as threads) are what this tier checks.
  OMP_THREAD_LIMIT=1 TSAN_OPTIONS="halt_on_error=1 history_size=7 suppressions=$root/tests/tsan.supp" \
    ctest --test-dir "$root/build-tsan" --output-on-failure -j "$jobs" -L concurrency --timeout 900
fi
