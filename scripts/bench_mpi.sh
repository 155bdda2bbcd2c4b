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
echo "bench_mpi: $(nproc) cores, $(uname -m), $ROUNDS rounds, work in $WORK"

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
# field NAME: the number after "NAME": on the last line of stdin (the --json line).
field() { tail -n 1 | grep -o "\"$1\":[-0-9.e+]*" | head -n 1 | cut -d: -f2; }

: >"$WORK/results.txt"
for round in $(seq 1 "$ROUNDS"); do
  for np in 1 2; do
    out=$WORK/f$np.tfs
    rm -f "$out"
    start=$(date +%s.%N)
    fps=$(run "$np" encode --model "$MODEL" --data "$DATA" --out "$out" --threads 1 --json \
            2>>"$WORK/log.txt" | field frames_per_s)
    wall=$(echo "$start $(date +%s.%N)" | awk '{printf "%.3f", $2 - $1}')
    rm -f "$WORK"/m$np.tfm*
    step=$(run "$np" train --data "$DATA" --sensors bubble --out "$WORK/m$np.tfm" --preset small \
             --steps "$STEPS" --threads 1 --seed 1 --json 2>>"$WORK/log.txt" | field seconds_per_step)
    echo "round $round np=$np: encode $fps frames/s ($FRAMES frames, command wall $wall s), train $step s/step"
    echo "$np encode $fps" >>"$WORK/results.txt"
    echo "$np wall $wall" >>"$WORK/results.txt"
    echo "$np step $step" >>"$WORK/results.txt"
  done
  cmp -s "$WORK/f1.tfs" "$WORK/f2.tfs" || { echo "bench_mpi: np=1 and np=2 functasets differ"; exit 1; }
  cmp -s "$WORK/m1.tfm" "$WORK/m2.tfm" || { echo "bench_mpi: np=1 and np=2 models differ"; exit 1; }
done

# stats NP WHAT: "median min max" of the figure over the rounds.
stats() {
  awk -v np="$1" -v what="$2" '$1 == np && $2 == what { print $3 }' "$WORK/results.txt" | sort -g |
    awk '{ v[NR] = $1 } END { m = NR % 2 ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2;
                              printf "%.4g %.4g %.4g", m, v[1], v[NR] }'
}
echo
echo "medians over $ROUNDS rounds (range min-max); functasets and models identical at np=1 and np=2"
report() {  # report WHAT LABEL UNIT HIGHER_IS_BETTER
  read -r m1 lo1 hi1 <<<"$(stats 1 "$1")"
  read -r m2 lo2 hi2 <<<"$(stats 2 "$1")"
  speedup=$(awk -v a="$m1" -v b="$m2" -v up="$4" 'BEGIN { printf "%.2f", up ? b / a : a / b }')
  printf "%-22s np=1 %8s %-8s (%s-%s)   np=2 %8s (%s-%s)   speed-up %sx\n" \
    "$2" "$m1" "$3" "$lo1" "$hi1" "$m2" "$lo2" "$hi2" "$speedup"
}
report encode "encode throughput" "frames/s" 1
report wall "encode command wall" "s" 0
report step "train step (batch 32)" "s" 0
