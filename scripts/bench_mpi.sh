#!/usr/bin/env bash
# The speed-up of `mpirun -np 2` over one process on this machine (docs/SCALING.md):
# encode throughput (frames/s) and the time of one training step at the same global
# batch, every process on one thread. np = 1 (a plain process) and np = 2 (mpirun)
# alternate for ROUNDS rounds, so both see the same machine load; the script prints each
# run, then the median and range (min-max) of each figure and the speed-up of the
# medians, and checks that both process counts wrote the same functaset bytes.
#
#   bash scripts/bench_mpi.sh                       # 5 rounds
#   ROUNDS=9 FRAMES_PER_TOOL=20 STEPS=40 bash scripts/bench_mpi.sh
#
# Encode: models/pretrained/default.tfm (the small preset: 64 x 3 SIREN, d = 64, both
# sensors at their working resolution) on a synthetic dataset of FRAMES_PER_TOOL
# contacts per tool, all twelve tools, both sensors (24 FRAMES_PER_TOOL frames).
# Train: the small preset on the bubble frames of that dataset, STEPS steps of batch 32,
# the mean step time that `train --json` reports (seconds_per_step: the batch's
# meta-gradients, their exchange and the Adam step; loading and monitoring excluded).
# Needs a build with MPI (scripts/build.sh finds Open MPI when installed).
set -euo pipefail
cd "$(dirname "$0")/.."
ROUNDS=${ROUNDS:-5}
FRAMES_PER_TOOL=${FRAMES_PER_TOOL:-10}
STEPS=${STEPS:-30}
WORK=${WORK:-$(mktemp -d /tmp/tactfunc_bench_mpi.XXXXXX)}
TF=$PWD/build/bin/tactfunc
MODEL=$PWD/models/pretrained/default.tfm
test -x "$TF" || bash scripts/build.sh
MPIRUN=${MPIRUN:-mpirun}
command -v "$MPIRUN" >/dev/null || { echo "bench_mpi: no $MPIRUN (install openmpi-bin)"; exit 1; }
# One thread per process: the ranks are the parallelism measured here.
export OMP_NUM_THREADS=1 CI=true
# Open MPI refuses root unless told (containers, CI).
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
mkdir -p "$WORK"
echo "bench_mpi: $(getconf _NPROCESSORS_ONLN) cores, $(uname -m), $ROUNDS rounds, work in $WORK"
# Other work on the machine takes cores from the processes measured: say how much.
echo "bench_mpi: load average at the start: $(cut -d' ' -f1-3 /proc/loadavg)"

DATA=$WORK/data
if [ ! -f "$DATA/dataset.json" ]; then
  "$TF" synth --out "$DATA" --frames-per-tool "$FRAMES_PER_TOOL" --seed 3 --threads 0 \
    --overwrite >/dev/null
fi
FRAMES=$(( FRAMES_PER_TOOL * 12 * 2 ))

# run NP ARGS...: the command as one plain process (NP = 1) or under mpirun.
run() {
  local np=$1; shift
  if [ "$np" = 1 ]; then "$TF" "$@"; else "$MPIRUN" -np "$np" --oversubscribe "$TF" "$@"; fi
}
# field NAME FILE: the number after "NAME": on the last line of FILE (the --json line).
field() { tail -n 1 "$2" | grep -o "\"$1\":[-0-9.e+]*" | head -n 1 | cut -d: -f2; }

# Other work on the machine takes cores from the processes measured. Per run: the CPU
# time the whole machine spent (/proc/stat) minus this script's children's (its
# /proc/PID/stat cutime + cstime), over the wall time = the cores others used meanwhile.
HZ=$(getconf CLK_TCK)
busy_ticks() { awk '/^cpu / { print $2 + $3 + $4 + $7 + $8 + $9 }' /proc/stat; }
our_ticks() { awk '{ print $16 + $17 }' "/proc/$$/stat"; }
# measure NP ARGS...: runs the command, its stdout to $WORK/last.txt; sets WALL (s) and
# OTHER (cores used by other processes meanwhile).
measure() {
  local busy0 ours0 start
  busy0=$(busy_ticks); ours0=$(our_ticks); start=$(date +%s.%N)
  run "$@" >"$WORK/last.txt" 2>>"$WORK/log.txt"
  WALL=$(echo "$start $(date +%s.%N)" | awk '{ printf "%.3f", $2 - $1 }')
  OTHER=$(awk -v b0="$busy0" -v b1="$(busy_ticks)" -v o0="$ours0" -v o1="$(our_ticks)" \
            -v hz="$HZ" -v wall="$WALL" \
            'BEGIN { x = ((b1 - b0) - (o1 - o0)) / hz / wall; printf "%.2f", x < 0 ? 0 : x }')
}

# results.txt: "round np figure value other_cores" lines.
: >"$WORK/results.txt"
for round in $(seq 1 "$ROUNDS"); do
  for np in 1 2; do
    rm -f "$WORK/f$np.tfs" "$WORK"/m$np.tfm*
    measure "$np" encode --model "$MODEL" --data "$DATA" --out "$WORK/f$np.tfs" --threads 1 --json
    fps=$(field frames_per_s "$WORK/last.txt")
    echo "$round $np encode $fps $OTHER" >>"$WORK/results.txt"
    echo "$round $np wall $WALL $OTHER" >>"$WORK/results.txt"
    encode_other=$OTHER encode_wall=$WALL
    measure "$np" train --data "$DATA" --sensors bubble --out "$WORK/m$np.tfm" --preset small \
      --steps "$STEPS" --threads 1 --seed 1 --json
    step=$(field seconds_per_step "$WORK/last.txt")
    echo "$round $np step $step $OTHER" >>"$WORK/results.txt"
    echo "round $round np=$np: encode $fps frames/s ($FRAMES frames, command wall $encode_wall s," \
         "other load $encode_other cores), train $step s/step (other load $OTHER cores)"
  done
  cmp -s "$WORK/f1.tfs" "$WORK/f2.tfs" || { echo "bench_mpi: np=1 and np=2 functasets differ"; exit 1; }
  cmp -s "$WORK/m1.tfm" "$WORK/m2.tfm" || { echo "bench_mpi: np=1 and np=2 models differ"; exit 1; }
done

# A quiet round: other processes used less than QUIET cores during each of its runs of
# the figure (both process counts).
QUIET=${QUIET:-0.25}
awk -v q="$QUIET" '{ if ($5 >= q) noisy[$1 " " $3] = 1; line[NR] = $0; key[NR] = $1 " " $3 }
  END { for (i = 1; i <= NR; ++i) if (!(key[i] in noisy)) print line[i] }' \
  "$WORK/results.txt" >"$WORK/quiet.txt"

# stats FILE NP WHAT: "median min max count" of the figure over the rounds in FILE.
stats() {
  awk -v np="$2" -v what="$3" '$2 == np && $3 == what { print $4 }' "$1" | sort -g |
    awk '{ v[NR] = $1 } END { if (NR == 0) { printf "- - - 0"; exit }
                              m = NR % 2 ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2;
                              printf "%.4g %.4g %.4g %d", m, v[1], v[NR], NR }'
}
echo
echo "bench_mpi: load average at the end: $(cut -d' ' -f1-3 /proc/loadavg)"
report() {  # report FILE WHAT LABEL UNIT HIGHER_IS_BETTER
  read -r m1 lo1 hi1 n1 <<<"$(stats "$1" 1 "$2")"
  read -r m2 lo2 hi2 n2 <<<"$(stats "$1" 2 "$2")"
  speedup=$(awk -v a="$m1" -v b="$m2" -v up="$5" \
              'BEGIN { if (a == "-" || b == "-") print "-"; else printf "%.2f", up ? b / a : a / b }')
  printf "%-22s np=1 %8s %-8s (%s-%s)   np=2 %8s (%s-%s)   speed-up %sx   [%s rounds]\n" \
    "$3" "$m1" "$4" "$lo1" "$hi1" "$m2" "$lo2" "$hi2" "$speedup" "$n1"
}
for set in all quiet; do
  file=$WORK/results.txt
  title="medians over all $ROUNDS rounds (range min-max)"
  if [ "$set" = quiet ]; then
    file=$WORK/quiet.txt
    title="medians over the quiet rounds (other processes below $QUIET cores in both runs)"
  fi
  echo "$title:"
  report "$file" encode "encode throughput" "frames/s" 1
  report "$file" wall "encode command wall" "s" 0
  report "$file" step "train step (batch 32)" "s" 0
done
echo "functasets and models identical at np=1 and np=2 in every round"

# The paper's dataset from these medians: PAPER_PAIRED paired frames (two sensors each)
# and the default preset's 16000 steps per sensor. Encoding is frames x the measured
# time per frame; a machine of two processes runs at the np=2 rate and N machines at N
# times it (frames are independent; each round's exchange carries only the latents).
# A training step does not depend on the dataset's size: over P processes it costs
# t1 / P + c, where c = t2 - t1 / 2 is the exchange overhead measured at np=2 here
# (loopback: a network adds its transfer of the batch's gradients, 2.7 MB a step).
PAPER_PAIRED=${PAPER_PAIRED:-32264}
# From the quiet rounds' medians where there are some, else from all rounds'.
file=$WORK/quiet.txt
{ grep -q " encode " "$file" && grep -q " step " "$file"; } || file=$WORK/results.txt
read -r e1 _ _ _ <<<"$(stats "$file" 1 encode)"
read -r e2 _ _ _ <<<"$(stats "$file" 2 encode)"
read -r t1 _ _ _ <<<"$(stats "$file" 1 step)"
read -r t2 _ _ _ <<<"$(stats "$file" 2 step)"
echo
echo "projection to $PAPER_PAIRED paired frames ($(( PAPER_PAIRED * 2 )) frames), hours" \
     "(from $(basename "$file" .txt)):"
awk -v n="$PAPER_PAIRED" -v e1="$e1" -v e2="$e2" -v t1="$t1" -v t2="$t2" 'BEGIN {
  frames = 2 * n; steps = 2 * 16000; c = t2 - t1 / 2; if (c < 0) c = 0
  printf "  %-44s %8.2f\n", "encode, one process (np=1 rate)", frames / e1 / 3600
  printf "  %-44s %8.2f\n", "encode, one 2-core machine (np=2 rate)", frames / e2 / 3600
  for (m = 4; m <= 16; m *= 4)
    printf "  %-44s %8.2f\n", "encode, " m " such machines", frames / (m * e2) / 3600
  printf "  %-44s %8.2f\n", "train 2 x 16000 steps, one process", steps * t1 / 3600
  printf "  %-44s %8.2f\n", "train, one 2-core machine (np=2)", steps * t2 / 3600
  for (m = 4; m <= 16; m *= 4)
    printf "  %-44s %8.2f\n", "train, " m " machines (" 2 * m " processes)", steps * (t1 / (2 * m) + c) / 3600
  printf "  (per frame %.1f ms on one process; exchange overhead c = %.1f ms a step)\n", 1000 / e1, 1000 * c
}'
