#!/usr/bin/env bash
# The speed-up of `mpirun -np 2` over one process for `tactfunc eval` and `tactfunc
# recon` on this machine (docs/SCALING.md), every process on one thread (--threads 1).
# np = 1 (a plain process) and np = 2 (mpirun) alternate for ROUNDS rounds, so both see
# the same machine load; the script prints each run with the cores other programs used
# meanwhile, then the median and range (min-max) of each figure and the speed-up of the
# medians, and checks in every round that both process counts wrote the same files
# (table.json but for its PCA fit seconds).
#
#   bash scripts/bench_mpi_eval.sh                  # 5 rounds
#   ROUNDS=9 FRAMES_PER_TOOL=10 bash scripts/bench_mpi_eval.sh
#
# Inputs: models/pretrained/default.tfm (the small preset, d = 64) and its pose model
# models/pretrained/pose_bubble.tpm on a synthetic dataset of FRAMES_PER_TOOL contacts per
# tool, all twelve tools, both sensors, 40% of each tool's contacts in the test split
# (24 FRAMES_PER_TOOL frames), and its functaset (encoded once, not timed). The pose
# model reads ceres:10 latents and the functaset holds meta_sgd:3 ones, so eval re-fits
# every bubble frame: the per-frame fits are most of its work. The figures are the wall
# time of the whole command (loading the inputs, mpirun's start and the writes included)
# and the CPU time all its processes used (user + system; at np = 2 it includes the work
# every process repeats and the waits in the exchanges): with two free cores the wall
# time at np = 2 approaches half that CPU time, and on a busy machine the CPU time still
# says what the second process costs.
# Needs a build with MPI (scripts/build.sh finds Open MPI when installed).
set -euo pipefail
cd "$(dirname "$0")/.."
ROUNDS=${ROUNDS:-5}
FRAMES_PER_TOOL=${FRAMES_PER_TOOL:-5}
WORK=${WORK:-$(mktemp -d /tmp/tactfunc_bench_mpi_eval.XXXXXX)}
TF=$PWD/build/bin/tactfunc
MODEL=$PWD/models/pretrained/default.tfm
POSE=$PWD/models/pretrained/pose_bubble.tpm
test -x "$TF" || bash scripts/build.sh
MPIRUN=${MPIRUN:-mpirun}
command -v "$MPIRUN" >/dev/null || { echo "bench_mpi_eval: no $MPIRUN (install openmpi-bin)"; exit 1; }
# One thread per process: the ranks are the parallelism measured here.
export OMP_NUM_THREADS=1 CI=true
# Open MPI refuses root unless told (containers, CI).
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
mkdir -p "$WORK"
echo "bench_mpi_eval: $(getconf _NPROCESSORS_ONLN) cores, $(uname -m), $ROUNDS rounds, work in $WORK"
echo "bench_mpi_eval: load average at the start: $(cut -d' ' -f1-3 /proc/loadavg)"

DATA=$WORK/data
if [ ! -f "$DATA/dataset.json" ]; then
  "$TF" synth --out "$DATA" --frames-per-tool "$FRAMES_PER_TOOL" --test-fraction 0.4 --seed 3 \
    --threads 0 --overwrite >/dev/null
fi
FUNCTASET=$WORK/f.tfs
[ -f "$FUNCTASET" ] || "$TF" encode --model "$MODEL" --data "$DATA" --out "$FUNCTASET" >/dev/null
FRAMES=$(( FRAMES_PER_TOOL * 12 * 2 ))

# run NP ARGS...: the command as one plain process (NP = 1) or under mpirun.
run() {
  local np=$1; shift
  if [ "$np" = 1 ]; then "$TF" "$@"; else "$MPIRUN" -np "$np" --oversubscribe "$TF" "$@"; fi
}
# Per run: the CPU time the whole machine spent (/proc/stat) minus this script's
# children's (its /proc/PID/stat cutime + cstime), over the wall time = the cores other
# programs used meanwhile.
HZ=$(getconf CLK_TCK)
busy_ticks() { awk '/^cpu / { print $2 + $3 + $4 + $7 + $8 + $9 }' /proc/stat; }
our_ticks() { awk '{ print $16 + $17 }' "/proc/$$/stat"; }
# measure NP ARGS...: runs the command; sets WALL (s), CPU (s, all its processes) and
# OTHER (cores used by others).
measure() {
  local busy0 ours0 start
  busy0=$(busy_ticks); ours0=$(our_ticks); start=$(date +%s.%N)
  run "$@" >"$WORK/last.txt" 2>>"$WORK/log.txt"
  WALL=$(echo "$start $(date +%s.%N)" | awk '{ printf "%.3f", $2 - $1 }')
  local busy1 ours1
  busy1=$(busy_ticks); ours1=$(our_ticks)
  CPU=$(awk -v o0="$ours0" -v o1="$ours1" -v hz="$HZ" 'BEGIN { printf "%.2f", (o1 - o0) / hz }')
  OTHER=$(awk -v b0="$busy0" -v b1="$busy1" -v o0="$ours0" -v o1="$ours1" \
            -v hz="$HZ" -v wall="$WALL" \
            'BEGIN { x = ((b1 - b0) - (o1 - o0)) / hz / wall; printf "%.2f", x < 0 ? 0 : x }')
}
# same_outputs A B: the files of folders A and B are the same bytes, table.json but for
# its "fit_seconds" lines (the PCA fit's time).
same_outputs() {
  local f
  for f in "$1"/*; do
    if [ "$(basename "$f")" = table.json ]; then
      cmp -s <(grep -v '"fit_seconds"' "$f") <(grep -v '"fit_seconds"' "$2/table.json") || return 1
    else
      cmp -s "$f" "$2/$(basename "$f")" || return 1
    fi
  done
  [ "$(ls "$1")" = "$(ls "$2")" ]
}

# results.txt: "round np figure value other_cores" lines.
: >"$WORK/results.txt"
for round in $(seq 1 "$ROUNDS"); do
  for np in 1 2; do
    # The same --out for both process counts (table.md quotes the command line).
    rm -rf "$WORK/eval" "$WORK/recon"
    measure "$np" eval --data "$DATA" --model "$MODEL" --functaset "$FUNCTASET" \
      --pose-model "$POSE" --out "$WORK/eval" --threads 1
    echo "$round $np eval $WALL $OTHER" >>"$WORK/results.txt"
    echo "$round $np eval_cpu $CPU $OTHER" >>"$WORK/results.txt"
    eval_wall=$WALL eval_other=$OTHER eval_cpu=$CPU
    measure "$np" recon --model "$MODEL" --functaset "$FUNCTASET" --data "$DATA" \
      --out "$WORK/recon" --threads 1
    echo "$round $np recon $WALL $OTHER" >>"$WORK/results.txt"
    echo "$round $np recon_cpu $CPU $OTHER" >>"$WORK/results.txt"
    echo "round $round np=$np: eval $eval_wall s, $eval_cpu CPU-s (other load $eval_other cores)," \
         "recon $WALL s, $CPU CPU-s (other load $OTHER cores), $FRAMES frames"
    rm -rf "$WORK/eval$np" "$WORK/recon$np"
    mv "$WORK/eval" "$WORK/eval$np"
    mv "$WORK/recon" "$WORK/recon$np"
  done
  same_outputs "$WORK/eval1" "$WORK/eval2" || { echo "bench_mpi_eval: np=1 and np=2 eval outputs differ"; exit 1; }
  same_outputs "$WORK/recon1" "$WORK/recon2" || { echo "bench_mpi_eval: np=1 and np=2 recon outputs differ"; exit 1; }
done

# stats NP WHAT: "median min max count" of the figure over the rounds.
stats() {
  awk -v np="$1" -v what="$2" '$2 == np && $3 == what { print $4 }' "$WORK/results.txt" | sort -g |
    awk '{ v[NR] = $1 } END { if (NR == 0) { printf "- - - 0"; exit }
                              m = NR % 2 ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2;
                              printf "%.4g %.4g %.4g %d", m, v[1], v[NR], NR }'
}
# other NP WHAT: the median of the other programs' cores over that figure's runs.
other() {
  awk -v np="$1" -v what="$2" '$2 == np && $3 == what { print $5 }' "$WORK/results.txt" | sort -g |
    awk '{ v[NR] = $1 } END { m = NR % 2 ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2;
                              printf "%.2f", m }'
}
echo
echo "bench_mpi_eval: load average at the end: $(cut -d' ' -f1-3 /proc/loadavg)"
echo "medians over all $ROUNDS rounds (range min-max); wall: the command's wall time," \
     "cpu: the CPU time of all its processes (np=2 / np=1 = what sharing costs):"
for what in eval eval_cpu recon recon_cpu; do
  read -r m1 lo1 hi1 n1 <<<"$(stats 1 "$what")"
  read -r m2 lo2 hi2 _ <<<"$(stats 2 "$what")"
  case $what in
    *_cpu) ratio="cpu ratio $(awk -v a="$m1" -v b="$m2" 'BEGIN { printf "%.2f", b / a }')" ;;
    *) ratio="speed-up $(awk -v a="$m1" -v b="$m2" 'BEGIN { printf "%.2f", a / b }')x" ;;
  esac
  printf "%-9s np=1 %7s s (%s-%s)   np=2 %7s s (%s-%s)   %s   [%s rounds; other load median %s / %s cores]\n" \
    "$what" "$m1" "$lo1" "$hi1" "$m2" "$lo2" "$hi2" "$ratio" "$n1" \
    "$(other 1 "$what")" "$(other 2 "$what")"
done
echo "eval and recon outputs identical at np=1 and np=2 in every round"
