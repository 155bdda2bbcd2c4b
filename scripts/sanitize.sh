#!/usr/bin/env bash
# Runs the test suite under AddressSanitizer and UBSan (docs/RELIABILITY.md).
#
#   scripts/sanitize.sh [CTEST_ARGS ...]      e.g. scripts/sanitize.sh -R 'estimation\.'
#   TARGETS="samplers_tests ..." scripts/sanitize.sh -R samplers   # build only those
#
# Configures and builds build-sanitize/ with -DTACTFUNC_SANITIZE=ON (gcc or clang, -O1;
# MPI off, the codecs linked in; every target, or the test executables TARGETS names
# and what they link), then runs ctest there with CTEST_ARGS (default: every
# test but the install test, whose consumer is not sanitized; the fuzz targets' replays,
# fuzz.replay.*, run sanitized too). A heap read after free, an overflow
# or undefined behaviour stops the test with the sanitizer's report and fails it. This
# run looks for memory errors, not leaks: leak checking is off unless ASAN_OPTIONS says
# otherwise. Everything runs under `nice -n 10`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
jobs=$(nproc)
# -O1: the sanitizers' usual level; -O3 with them compiles several times slower.
nice -n 10 cmake -S . -B build-sanitize -DTACTFUNC_SANITIZE=ON -DTACTFUNC_MPI=OFF \
  -DTACTFUNC_BUILD_EXAMPLES=OFF -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g -DNDEBUG" >/dev/null
if [[ -n "${TARGETS:-}" ]]; then
  # shellcheck disable=SC2086
  nice -n 10 cmake --build build-sanitize -j"$jobs" --target $TARGETS
else
  nice -n 10 cmake --build build-sanitize -j"$jobs"
fi
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=0:abort_on_error=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
cd build-sanitize
if [[ $# -eq 0 ]]; then set -- -E '^install\.'; fi
nice -n 10 ctest --output-on-failure -j"$jobs" --timeout 3600 "$@"
