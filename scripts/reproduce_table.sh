#!/usr/bin/env bash
# Reproduces the paper's Table I on synthetic paired data, from nothing (docs/RESULTS.md):
#   synth -> train (one model per latent size) -> encode -> train-pose -> eval
# printing every command it runs. Everything lands in $WORK; the table in $WORK/table/
# (table.md, table.json, rate_distortion.png).
#
# Settings (environment variables):
#   WORK             work folder (default /tmp/tactfunc_table)
#   FRAMES_PER_TOOL  contacts per tool, 12 tools (default 150: the pretrained model's data)
#   STEPS            meta-learning steps per model (default 2000)
#   LATENT_DIM       latent floats of the model of the table (default 64)
#   LATENT_DIMS      extra latent sizes for the rate-distortion picture (default "16 32 128";
#                    "" for none); each is one more train + encode
#   SEED             seed of the data and the models (default 1)
#   THREADS          worker threads (default: every core)
#   TF               the tactfunc program (default build/bin/tactfunc; built if missing)
# A small run that finishes in a few minutes:
#   FRAMES_PER_TOOL=20 STEPS=300 LATENT_DIMS=16 bash scripts/reproduce_table.sh
set -euo pipefail
cd "$(dirname "$0")/.."
WORK=${WORK:-/tmp/tactfunc_table}
FRAMES_PER_TOOL=${FRAMES_PER_TOOL:-150}
STEPS=${STEPS:-2000}
LATENT_DIM=${LATENT_DIM:-64}
LATENT_DIMS=${LATENT_DIMS-16 32 128}
SEED=${SEED:-1}
THREADS=${THREADS:-0}
TF=${TF:-build/bin/tactfunc}
test -x "$TF" || bash scripts/build.sh

run() {
  echo "+ $*" >&2
  "$@"
}

mkdir -p "$WORK"
start=$(date +%s)
# The training settings of models/pretrained/default.tfm (scripts/train_pretrained.sh)
# but for --steps and --latent-dim.
train_args=(--preset small --pixels 512 --batch 32 --steps "$STEPS" --seed "$SEED"
            --threads "$THREADS")

run "$TF" synth --out "$WORK/data" --frames-per-tool "$FRAMES_PER_TOOL" --seed "$SEED" \
  --clean --overwrite --threads "$THREADS"
run "$TF" train --data "$WORK/data" --out "$WORK/d$LATENT_DIM.tfm" --latent-dim "$LATENT_DIM" \
  "${train_args[@]}"
run "$TF" encode --model "$WORK/d$LATENT_DIM.tfm" --data "$WORK/data" \
  --out "$WORK/d$LATENT_DIM.tfs" --threads "$THREADS"
run "$TF" train-pose --functaset "$WORK/d$LATENT_DIM.tfs" --out "$WORK/d$LATENT_DIM.tpm" \
  --sensor bubble --seed "$SEED"

extra=()
for d in $LATENT_DIMS; do
  [ "$d" = "$LATENT_DIM" ] && continue
  run "$TF" train --data "$WORK/data" --out "$WORK/d$d.tfm" --latent-dim "$d" "${train_args[@]}"
  run "$TF" encode --model "$WORK/d$d.tfm" --data "$WORK/data" --out "$WORK/d$d.tfs" \
    --threads "$THREADS"
  extra+=(--extra-functaset "$WORK/d$d.tfs" --extra-model "$WORK/d$d.tfm")
done

run "$TF" eval --data "$WORK/data" --model "$WORK/d$LATENT_DIM.tfm" \
  --functaset "$WORK/d$LATENT_DIM.tfs" --pose-model "$WORK/d$LATENT_DIM.tpm" \
  --out "$WORK/table" --threads "$THREADS" "${extra[@]}"
echo "reproduce_table: done in $(( $(date +%s) - start )) s" \
  "(FRAMES_PER_TOOL=$FRAMES_PER_TOOL STEPS=$STEPS LATENT_DIM=$LATENT_DIM" \
  "LATENT_DIMS=\"$LATENT_DIMS\" SEED=$SEED); table in $WORK/table/"
