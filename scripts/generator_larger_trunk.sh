#!/usr/bin/env bash
# The generator path through a larger Soft Bubble trunk (docs/POSES.md, "A larger trunk
# under the generator"): the committed Soft Bubble reconstruction trunk
# models/pretrained/bubble.tfm (the `default` preset: width 64, 3 layers, d = 128, 16,000
# steps; scripts/train_pretrained_bubble.sh) in place of the `small` one the pose models
# stand on (models/pretrained/default.tfm: d = 64, 4000 steps); the generator trained on it
# exactly as scripts/train_pretrained_generator.sh trains the committed one (same
# contacts, same options), and scored on the same 1,200 fresh contacts by eval-generator.
# This generator is the committed one since the study (scripts/train_pretrained_generator.sh
# writes it, the same weights); the script keeps the study's scoring beside it.
# About 10 minutes on 2 cores. Deterministic for the seeds.
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
MODEL=models/pretrained/bubble.tfm
run "$TF" encode --model "$MODEL" --data "$POSE_WORK/data" --out "$WORK/f.tfs" \
  --threads 2
run "$TF" train-generator --model "$MODEL" --functaset "$WORK/f.tfs" \
  --data "$POSE_WORK/data" --out "$WORK/g.tpg" --mode pixels \
  --hidden 256,256 --harmonics 8 --epochs 300 --pixel-frames 1000 --pixel-epochs 30 \
  --calibration-frames 60
run "$TF" eval-generator --model "$MODEL" --generator "$WORK/g.tpg" \
  --functaset "$WORK/f.tfs" --contacts-per-tool 100 --contacts-csv "$WORK/contacts.csv"
python3 scripts/generator_errors.py "$WORK/contacts.csv"
