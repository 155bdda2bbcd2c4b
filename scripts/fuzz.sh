#!/usr/bin/env bash
# Fuzzes tactfunc's readers with libFuzzer under AddressSanitizer and UBSan
# (tests/fuzz/, docs/RELIABILITY.md).
#
#   scripts/fuzz.sh [--runs N | --seconds S] [TARGET ...]
#   scripts/fuzz.sh --smoke        # every target for a few seconds (ctest's fuzz.smoke
#                                  # when configured with -DTACTFUNC_FUZZ_SMOKE=ON)
#
# Configures and builds build-fuzz/ with clang (-DTACTFUNC_FUZZ=ON; only the fuzz
# targets and the libraries they need), writes the seed corpora with tactfunc's own
# writers (build-fuzz/fuzz/make_seed_corpora), then runs each target ONE AT A TIME for
# N executions (--runs, default 1000000) or S seconds (--seconds), under `nice -n 15`.
# Targets: tensor_file model functaset pose_model knn_index labels_csv dataset image
# (default: all). Corpora grow in build-fuzz/corpus/<target>/; a crash is saved in
# build-fuzz/findings/<target>/ (with the run's log, last_run.log) and ends the script
# with exit 1. The smoke builds its own tree at -O0, build-fuzz-smoke/ (about half the
# compile time of -O2, which is all a few seconds of fuzzing need; docs/BUILD.md, "Build
# time"), and keeps its corpora and logs in build-fuzz-smoke/smoke/. Each finished
# long run's count and last libFuzzer line (coverage) is appended to build-fuzz/fuzz.log.
# Exit 77 (a skip for ctest) if clang++ is not installed.
set -euo pipefail
cd "$(dirname "$0")/.."

runs=1000000
seconds=""
smoke=0
targets=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    --runs) runs="$2"; shift 2 ;;
    --seconds) seconds="$2"; shift 2 ;;
    --smoke) smoke=1; seconds=4; shift ;;
    -h|--help) sed -n '2,20p' "$0"; exit 0 ;;
    -*) echo "fuzz.sh: unknown flag $1" >&2; exit 2 ;;
    *) targets+=("$1"); shift ;;
  esac
done
all=(tensor_file model functaset pose_model knn_index labels_csv dataset image)
[[ ${#targets[@]} -eq 0 ]] && targets=("${all[@]}")

if ! command -v clang++ >/dev/null 2>&1; then
  echo "fuzz.sh: SKIPPED: clang++ is not installed (apt-get install clang); the fuzz targets need libFuzzer"
  exit 77
fi

build=build-fuzz
optimisation=()
if [[ $smoke -eq 1 ]]; then
  build=build-fuzz-smoke
  optimisation=("-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O0 -DNDEBUG")
fi
launcher=()
command -v ccache >/dev/null 2>&1 && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
if [[ ! -f $build/CMakeCache.txt ]]; then
  CC=clang CXX=clang++ cmake -S . -B $build -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DTACTFUNC_FUZZ=ON -DTACTFUNC_NATIVE=OFF -DTACTFUNC_BUILD_TESTS=OFF \
    -DTACTFUNC_BUILD_APPS=OFF -DTACTFUNC_BUILD_EXAMPLES=OFF "${optimisation[@]}" "${launcher[@]}" \
    >$build.configure.log 2>&1 || { cat $build.configure.log; exit 1; }
fi
nice -n 15 cmake --build $build --target tactfunc_fuzzers -j"$(nproc)" 2>&1 |
  { grep -Ev '^\[ *[0-9]+%\]|^-- |warning: unknown warning option|^[0-9]+ warnings? generated' || true; }

seeds=$build/seeds
rm -rf $seeds
ASAN_OPTIONS=detect_leaks=0 $build/fuzz/make_seed_corpora $seeds >/dev/null
export ASAN_OPTIONS=detect_leaks=1:allocator_may_return_null=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
for target in "${targets[@]}"; do
  binary=$build/fuzz/${target}_fuzzer
  [[ -x $binary ]] || { echo "fuzz.sh: no target '$target' (one of: ${all[*]})" >&2; exit 2; }
  corpus=$build/corpus/$target
  findings=$build/findings/$target
  if [[ $smoke -eq 1 ]]; then  # leaves the long runs' corpora and logs alone
    corpus=$build/smoke/corpus/$target
    findings=$build/smoke/findings/$target
  fi
  mkdir -p "$corpus" "$findings"
  budget=(-runs="$runs")
  [[ -n $seconds ]] && budget=(-max_total_time="$seconds")
  log=$findings/last_run.log
  start=$(date +%s)
  # -rss_limit_mb: a reader that allocates beyond its input is a finding too.
  if ! nice -n 15 "$binary" "$corpus" "$seeds/$target" "${budget[@]}" -rss_limit_mb=2048 \
      -timeout=30 -max_len=8192 -artifact_prefix="$findings/" \
      -print_final_stats=1 >"$log" 2>&1; then
    tail -40 "$log"
    echo "fuzz.sh: $target: FINDING (input saved in $findings/)" >&2
    exit 1
  fi
  executions=$(grep -ao 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || true)
  line=$(grep -aE '^#[0-9]+[[:space:]]+(DONE|INITED)' "$log" | tail -1 || true)
  summary="$(date -u +%FT%TZ) $target: $executions executions in $(( $(date +%s) - start )) s, 0 crashes; $line"
  echo "fuzz.sh: $summary"
  [[ $smoke -eq 1 ]] || echo "$summary" >>$build/fuzz.log
done
