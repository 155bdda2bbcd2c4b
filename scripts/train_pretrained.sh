#!/usr/bin/env bash
# Reproduces models/pretrained/default.tfm, the trunk the README demo uses:
# the default synthetic paired dataset (12 tools x 150 contacts, seed 1, with noise-free
# copies), then `tactfunc train` with the options below. Deterministic for the seed.
# Wall time and PSNR of the committed model: docs/RESULTS_RECONSTRUCTION.md.
set -euo pipefail
cd "$(dirname "$0")/.."
WORK=${WORK:-/tmp/tactfunc_pretrained}
TF=build/bin/tactfunc
test -x "$TF" || bash scripts/build.sh
mkdir -p "$WORK"
"$TF" synth --out "$WORK/data" --frames-per-tool 150 --seed 1 --clean --overwrite
"$TF" train --data "$WORK/data" --out "$WORK/default.tfm" --preset small \
  --latent-dim 64 --pixels 512 --batch 32 --steps 4000 --checkpoint-every 500 --seed 1 "$@"
cp "$WORK/default.tfm" models/pretrained/default.tfm
echo "wrote models/pretrained/default.tfm (data and checkpoints in $WORK)"
