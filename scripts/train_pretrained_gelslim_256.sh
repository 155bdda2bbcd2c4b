#!/usr/bin/env bash
# Reproduces models/pretrained/gelslim_256.tfm, the GelSlim's photometric trunk for 256 B
# per frame: the recipe of models/pretrained/gelslim.tfm (scripts/train_pretrained_gelslim.sh:
# the same data, seed and 24000 steps) with a latent of d = 128 values and a SIREN of width
# 96 (docs/RESULTS_RECONSTRUCTION.md, "The GelSlim at 256 B per frame"), recording
# knn+adam:480 as the fit `encode` gives its frames (the 256 B target needs it; encode's
# rule would give 280 steps). Stored with `encode --latent-bytes 256`. Deterministic for
# the seed; about 32 minutes on 2 cores.
set -euo pipefail
NAME=gelslim_256 exec bash "$(dirname "$0")/train_pretrained_gelslim.sh" --latent-dim 128 \
  --width 96 --default-fit knn+adam:480 "$@"
