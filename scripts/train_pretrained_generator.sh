#!/usr/bin/env bash
# Reproduces models/pretrained/pose_generator_bubble.tpg, the pose-conditioned generator of
# the generator pose posterior (docs/POSES.md, "The generator path"), and the latent-only
# variant it was compared with. Data: 12 tools x 1000 Soft Bubble contacts, seed 2 (as
# scripts/train_pretrained_pose.sh), encoded with models/pretrained/default.tfm (the pose
# model's trunk: $WORK/f.tfs, the latent-only variant's) and with
# models/pretrained/bubble.tfm (the Soft Bubble's reconstruction trunk, d = 128:
# $WORK/f_bubble.tfs, the data of the generators committed before 2026-11-29); and
# 12 tools x GEN_FRAMES (4000) contacts of the same seed ($WORK/gen_data, which holds the
# 12,000 above), encoded with bubble.tfm into $WORK/f_gen.tfs: the committed generator is
# trained on them and renders through bubble.tfm (`pose --generator-model`), and f_gen.tfs
# is the labelled functaset of its k-NN starts (docs/POSES.md, "More contacts for the
# generator"); its kappa and tau are calibrated with the posterior's final stage on 1,024
# pixels, which the posterior then runs by default ("The final ranking on more pixels").
# About 14 minutes on 2 cores (the generator's training about 6 on one). Deterministic for
# the seeds.
set -euo pipefail
cd "$(dirname "$0")/.."
WORK=${WORK:-/tmp/pose_se2}
TF=build/bin/tactfunc
test -x "$TF" || bash scripts/build.sh
mkdir -p "$WORK"
run() { echo "+ $*"; "$@"; }
run "$TF" synth --out "$WORK/data" --frames-per-tool 1000 --sensors bubble --seed 2 --threads 1 --overwrite
run "$TF" encode --model models/pretrained/default.tfm --data "$WORK/data" --out "$WORK/f.tfs" --threads 1
run "$TF" train-generator --model models/pretrained/default.tfm --functaset "$WORK/f.tfs" \
  --data "$WORK/data" --out "$WORK/g_lat.tpg" --mode latents --epochs 100 --calibration-frames 60
run "$TF" encode --model models/pretrained/bubble.tfm --data "$WORK/data" --out "$WORK/f_bubble.tfs" \
  --threads 1
GEN_FRAMES=${GEN_FRAMES:-4000}
OUT=${OUT:-models/pretrained/pose_generator_bubble.tpg}  # another OUT for a variant
run "$TF" synth --out "$WORK/gen_data" --frames-per-tool "$GEN_FRAMES" --sensors bubble --seed 2 \
  --threads 2 --overwrite
run "$TF" encode --model models/pretrained/bubble.tfm --data "$WORK/gen_data" \
  --out "$WORK/f_gen.tfs" --threads 2
run "$TF" train-generator --model models/pretrained/bubble.tfm --functaset "$WORK/f_gen.tfs" \
  --data "$WORK/gen_data" --out "$OUT" --mode pixels \
  --hidden 256,256 --harmonics 8 --epochs 300 --pixel-frames "$GEN_FRAMES" --pixel-epochs 30 \
  --calibration-frames 600 --final-pixels 1024
