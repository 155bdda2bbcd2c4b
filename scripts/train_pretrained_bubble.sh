#!/usr/bin/env bash
# Reproduces models/pretrained/bubble.tfm, the Soft Bubble's committed reconstruction trunk:
# `train`'s default preset (width 64, 3 layers, d = 128 values, 16000 steps with the
# learning rate decayed to a tenth) on the Soft Bubble frames of the default synthetic
# dataset (12 tools x 150 contacts, seed 1, with noise-free copies, the same contacts as
# scripts/train_pretrained.sh). Stored as 8-bit codes (`encode --latent-precision uint8`)
# its latents take 128 B per frame, as the d = 64 float16 latents of
# models/pretrained/default.tfm do (docs/RESULTS_RECONSTRUCTION.md, "The Soft Bubble's
# committed trunk"). Deterministic for the seed; about 10-18 minutes on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
WORK=${WORK:-/tmp/tactfunc_pretrained_bubble}
TF=build/bin/tactfunc
test -x "$TF" || bash scripts/build.sh
mkdir -p "$WORK"
run() { echo "+ $*"; "$@"; }
run "$TF" synth --out "$WORK/data" --frames-per-tool 150 --sensors bubble --seed 1 --clean --overwrite
run "$TF" train --data "$WORK/data" --out "$WORK/bubble.tfm" --preset default --sensors bubble \
  --seed 1 --threads 2 "$@"
cp "$WORK/bubble.tfm" models/pretrained/bubble.tfm
echo "wrote models/pretrained/bubble.tfm (data in $WORK)"
