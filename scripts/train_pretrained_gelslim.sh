#!/usr/bin/env bash
# Reproduces models/pretrained/gelslim.tfm, the GelSlim's committed trunk: the photometric
# head (docs/REPRESENTATION.md, "Optical sensors: draw the indentation, then shade it"),
# which draws the gel's markers and shading ridges where the direct SIREN of
# models/pretrained/default.tfm draws a blurred shadow. Data: the GelSlim frames of the
# default synthetic dataset (12 tools x 150 contacts, seed 1, with noise-free copies, as
# scripts/train_pretrained.sh); `train --head photometric` with its defaults (d = 64 values,
# 128 B per frame; 24000 steps, the first 1000 with the markers at the working resolution,
# half of each frame's pixels drawn towards its contact) and the training latents'
# warm-start table, which `encode` starts its fits from.
# Deterministic for the seed; about 33 minutes on 2 cores. Flags after the script's name go
# to `train`; NAME=N writes models/pretrained/N.tfm instead (scripts/
# train_pretrained_gelslim_256.sh: the 256 B trunk).
set -euo pipefail
cd "$(dirname "$0")/.."
WORK=${WORK:-/tmp/tactfunc_pretrained_gelslim}
NAME=${NAME:-gelslim}
TF=build/bin/tactfunc
test -x "$TF" || bash scripts/build.sh
mkdir -p "$WORK"
run() { echo "+ $*"; "$@"; }
run "$TF" synth --out "$WORK/data" --frames-per-tool 150 --sensors gelslim --seed 1 --clean --overwrite
run "$TF" train --data "$WORK/data" --out "$WORK/$NAME.tfm" --head photometric --seed 1 \
  --threads 2 "$@"
cp "$WORK/$NAME.tfm" "models/pretrained/$NAME.tfm"
echo "wrote models/pretrained/$NAME.tfm (data in $WORK)"
