#!/usr/bin/env bash
# Where a fresh build's time goes (docs/BUILD.md, "Build time").
#
#   scripts/measure_build_time.sh OUT_DIR [CMAKE_ARGS ...]
#
# Configures a fresh Release build in OUT_DIR (which must not exist) with a compiler
# launcher that records each object's wall time, builds it with -j$(nproc), then prints
# the build's wall time and the compile seconds summed per part: the libraries, the
# `tactfunc` program, the test suites, the examples; and the ten
# slowest objects. The log is OUT_DIR/compile_times.log ("seconds object" per line).
# Extra arguments go to the configure step, e.g. -DTACTFUNC_NATIVE=OFF.
set -euo pipefail
if [[ ${1:-} == --wrap ]]; then  # the launcher: --wrap LOG COMPILER ARGS...
  log=$2; shift 2
  start=$(date +%s.%N)
  status=0
  "$@" || status=$?
  end=$(date +%s.%N)
  out=""
  args=("$@")
  for ((i = 0; i < ${#args[@]}; i++)); do
    [[ ${args[i]} == -o ]] && out=${args[i + 1]}
  done
  echo "$(awk -v a="$start" -v b="$end" 'BEGIN { printf "%.2f", b - a }') $out" >>"$log"
  exit $status
fi
[[ $# -ge 1 ]] || { sed -n '2,11p' "$0"; exit 2; }
out=$1; shift
[[ ! -e $out ]] || { echo "measure_build_time.sh: $out exists; give a new directory" >&2; exit 2; }
root=$(cd "$(dirname "$0")/.." && pwd)
script="$root/scripts/measure_build_time.sh"
mkdir -p "$out"
out=$(cd "$out" && pwd)
log=$out/compile_times.log
: >"$log"
cmake -S "$root" -B "$out" -DCMAKE_BUILD_TYPE=Release \
  "-DCMAKE_CXX_COMPILER_LAUNCHER=$script;--wrap;$log" "$@" >"$out/configure.log" 2>&1 ||
  { cat "$out/configure.log"; exit 1; }
start=$(date +%s)
cmake --build "$out" -j"$(nproc)" >"$out/build.log" 2>&1 || { tail -30 "$out/build.log"; exit 1; }
wall=$(( $(date +%s) - start ))
echo "build: ${wall} s wall on $(nproc) cores, $(wc -l <"$log") objects"
awk '{
  part = "libraries";
  if ($2 ~ /CMakeFiles\/tactfunc\.dir\//) part = "program (apps/)";
  else if ($2 ~ /_test\.dir\// || $2 ~ /^tests\//) part = "test suites";
  else if ($2 ~ /example/) part = "examples";
  sum[part] += $1; n[part]++; total += $1
} END {
  for (p in sum) printf "  %-20s %7.0f s compiling (%d objects)\n", p, sum[p], n[p];
  printf "  %-20s %7.0f s\n", "all", total
}' "$log"
echo "slowest objects:"
sort -rn "$log" | head -10 | awk '{ printf "  %6.1f s  %s\n", $1, $2 }'
