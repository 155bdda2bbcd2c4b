#!/usr/bin/env bash
# Reproduces models/pretrained/bubble_readout.tfm, the Soft Bubble trunk for storage: a
# readout trunk (a linear branch started as the PCA of 5,000 noise-free training frames,
# every fit the frame's projection shrunk by each component's Wiener gain, a SIREN of
# the `small` preset trained on top, whole frames, against the noise-free copies; d = 256)
# trained on 16,200 simulated contacts (12 tools x 1500, seed 1, with noise-free copies).
# Stored in allocated codes (`encode --latent-bytes 128` or 256) its latents take 128 or
# 256 B per frame (docs/RESULTS_RECONSTRUCTION.md, "The Soft Bubble's storage trunk";
# docs/REPRESENTATION.md, "Sharing the bytes among the latent's values"). It serves
# reconstruction; the pose paths stay on models/pretrained/default.tfm and bubble.tfm.
# Deterministic for the seed; about 3 minutes on one core.
set -euo pipefail
cd "$(dirname "$0")/.."
WORK=${WORK:-/tmp/tactfunc_pretrained_bubble_readout}
TF=build/bin/tactfunc
test -x "$TF" || bash scripts/build.sh
mkdir -p "$WORK"
run() { echo "+ $*"; "$@"; }
run "$TF" synth --out "$WORK/data" --frames-per-tool 1500 --sensors bubble --seed 1 --clean \
  --overwrite
# --preset storage: small's SIREN, --readout --readout-pca-frames 5000 --pixels 0 --batch 8
# --steps 1000 --latent-dim 256 --outer-clean --inner-steps 0 (docs/TRAINING.md, "Presets").
run "$TF" train --data "$WORK/data" --out "$WORK/bubble_readout.tfm" --preset storage \
  --sensors bubble --seed 1 --threads 1 "$@"
cp "$WORK/bubble_readout.tfm" models/pretrained/bubble_readout.tfm
echo "wrote models/pretrained/bubble_readout.tfm (data in $WORK)"
