#!/usr/bin/env bash
# The generator path through a larger Soft Bubble trunk (docs/POSES.md, "A larger trunk
# under the generator"): the `default` preset's trunk (width 64, 3 layers, d = 128,
# 16,000 steps) in place of the committed `small` one (d = 64, 4000 steps), trained on
# the same data as scripts/train_pretrained.sh (12 tools x 150 contacts, seed 1, Soft
# Bubble only); then the generator trained on it exactly as
# scripts/train_pretrained_generator.sh trains the committed one (same contacts, same
# options), and both scored on the same 1,200 fresh contacts by eval-generator.
# About 30 minutes on 2 cores (18 of them training the trunk). Deterministic for the seeds.
set -euo pipefail
cd "$(dirname "$0")/.."
WORK=${WORK:-/tmp/generator_larger_trunk}
POSE_WORK=${POSE_WORK:-/tmp/pose_se2}  # scripts/train_pretrained_generator.sh's data
TF=build/bin/tactfunc
test -x "$TF" || bash scripts/build.sh
mkdir -p "$WORK" "$POSE_WORK"
run() { echo "+ $*"; "$@"; }
if [ ! -f "$POSE_WORK/data/dataset.json" ]; then
  run "$TF" synth --out "$POSE_WORK/data" --frames-per-tool 1000 --sensors bubble --seed 2 \
    --threads 1 --overwrite
fi
run "$TF" synth --out "$WORK/trunk_data" --frames-per-tool 150 --sensors bubble --seed 1 \
  --clean --overwrite
run "$TF" train --data "$WORK/trunk_data" --out "$WORK/bubble_d128.tfm" --preset default \
  --sensors bubble --seed 1 --threads 2
run "$TF" encode --model "$WORK/bubble_d128.tfm" --data "$POSE_WORK/data" --out "$WORK/f.tfs" \
  --threads 2
run "$TF" train-generator --model "$WORK/bubble_d128.tfm" --functaset "$WORK/f.tfs" \
  --data "$POSE_WORK/data" --out "$WORK/g.tpg" --mode pixels \
  --hidden 256,256 --harmonics 8 --epochs 300 --pixel-frames 1000 --pixel-epochs 30 \
  --calibration-frames 60
run "$TF" eval-generator --model "$WORK/bubble_d128.tfm" --generator "$WORK/g.tpg" \
  --functaset "$WORK/f.tfs" --contacts-per-tool 100 --contacts-csv "$WORK/contacts.csv"
python3 scripts/generator_errors.py "$WORK/contacts.csv"
