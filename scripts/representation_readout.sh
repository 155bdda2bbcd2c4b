#!/usr/bin/env bash
# The representation study's readout-branch rows (docs/REPRESENTATION.md): a trunk trained
# with the linear readout branch (`train --readout`, started as the PCA of its training
# frames) on one simulated dataset, encoded and evaluated on a second one that no training
# run used, both sensors, against PCA at equal bytes per frame (float32 components) and
# against PCA codes stored as the latents are (same bits), noise-free frames.
#
#   bash scripts/representation_readout.sh [OUT_DIR] [STEPS] [LATENT_DIM] [PRECISION] [STRATEGY...]
#
# Defaults: /tmp/tactfunc_readout, 2000 steps, d = 64, float16, meta_sgd:3. Data:
# `synth --frames-per-tool 150 --clean`, seed 1 to train, seed 4242 to evaluate (its test
# split; its train split fits the PCA baselines). Training: `--preset small --readout
# --pixels 2048 --batch 8 --seed 1`. Every figure printed comes from the eval table.json
# named on its line.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-/tmp/tactfunc_readout}
steps=${2:-2000}
dim=${3:-64}
precision=${4:-float16}
shift $(( $# < 4 ? $# : 4 ))
strategies=("$@")
[ ${#strategies[@]} -gt 0 ] || strategies=(meta_sgd:3)
bin=build/bin/tactfunc
[ -x "$bin" ] || { echo "representation_readout: build first (bash scripts/build.sh)" >&2; exit 1; }
mkdir -p "$out"
for seed in 1 4242; do
  [ -f "$out/data$seed/dataset.json" ] ||
    "$bin" synth --out "$out/data$seed" --frames-per-tool 150 --seed "$seed" --clean >/dev/null
done
model="$out/readout_d${dim}_s${steps}.tfm"
if [ ! -f "$model" ]; then
  "$bin" train --data "$out/data1" --out "$model" --preset small --readout --pixels 2048 \
      --batch 8 --steps "$steps" --latent-dim "$dim" --seed 1 --checkpoint-every 200 \
      $( [ -f "$model.bubble.ckpt" ] || [ -f "$model.gelslim.ckpt" ] && echo --resume ) >&2
fi
for strategy in "${strategies[@]}"; do
  name="d${dim}_s${steps}_${precision}_${strategy/:/_}"
  "$bin" encode --model "$model" --data "$out/data4242" --out "$out/$name.tfs" \
      --strategy "$strategy" --latent-precision "$precision" >&2
  "$bin" eval --data "$out/data4242" --model "$model" --functaset "$out/$name.tfs" \
      --out "$out/eval_$name" >/dev/null
  python3 - "$out/eval_$name/table.json" "$strategy" "$precision" "$dim" <<'PY'
import json, sys
table = json.load(open(sys.argv[1]))
for sensor, t in table["targets"].items():
    a, s = t["psnr_3db_above_pca_clean"], t["psnr_3db_above_pca_same_bits_clean"]
    print(f"{sensor:8s} readout d={sys.argv[4]} "
          f"{sys.argv[3]} {sys.argv[2]}: {a['bytes_per_frame']:.0f} B/frame, noise-free: "
          f"TactFunc {a['tactfunc_db']:.2f} dB | PCA float32 {a['pca_db']:.2f} "
          f"(margin {a['margin_db']:+.2f}) | PCA same bits {s['pca_db']:.2f} "
          f"(margin {s['margin_db']:+.2f})  [{sys.argv[1]}]")
PY
done
