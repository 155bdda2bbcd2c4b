#!/usr/bin/env bash
# The representation study's spatial-latent rows (docs/REPRESENTATION.md): a trunk whose
# latent is (partly) a grid of local latents interpolated per pixel into the shifts
# (`train --spatial-latent GHxGWxC`, after Spatial Functa), trained on one simulated
# dataset, encoded and evaluated on a second one that no training run used, both sensors,
# against PCA at equal bytes per frame (float32 components) and against PCA codes stored
# as the latents are (same bits). The same data, budget and baselines as
# scripts/representation_readout.sh.
#
#   bash scripts/representation_spatial.sh [OUT_DIR] [STEPS] [GRID] [LATENT_DIM] [PRECISION] [STRATEGY...]
#
# Defaults: /tmp/tactfunc_spatial, 2000 steps, grid 4x4x4, d = 64 (d - GH*GW*C global
# values beside the grid), float16, meta_sgd:3. GRID `none` trains the global-latent
# trunk of the same budget (no --spatial-latent), the control row; a GRID ending in
# `+readout` (e.g. 3x4x4+readout) adds the linear readout branch (`train --readout`,
# scripts/representation_readout.sh). Data: `synth
# --frames-per-tool 150 --clean`, seed 1 to train, seed 4242 to evaluate (its test split;
# its train split fits the PCA baselines). Training: `--preset small --pixels 2048 --batch 8 --seed 1`. Every
# PSNR printed comes from the eval table.json named on its line; the training seconds
# from `train --json`, the encode rate from `encode --json` (both sensors together).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-/tmp/tactfunc_spatial}
steps=${2:-2000}
grid=${3:-4x4x4}
dim=${4:-64}
precision=${5:-float16}
shift $(( $# < 5 ? $# : 5 ))
strategies=("$@")
[ ${#strategies[@]} -gt 0 ] || strategies=(meta_sgd:3)
bin=build/bin/tactfunc
[ -x "$bin" ] || { echo "representation_spatial: build first (bash scripts/build.sh)" >&2; exit 1; }
mkdir -p "$out"
for seed in 1 4242; do
  [ -f "$out/data$seed/dataset.json" ] ||
    "$bin" synth --out "$out/data$seed" --frames-per-tool 150 --seed "$seed" --clean >/dev/null
done
readout=()
spec=$grid
if [ "${grid%+readout}" != "$grid" ]; then readout=(--readout); grid=${grid%+readout}; fi
tag=${spec/+/_}
model="$out/spatial_${tag}_d${dim}_s${steps}.tfm"
if [ ! -f "$model" ]; then
  "$bin" train --data "$out/data1" --out "$model" --preset small \
      $( [ "$grid" = none ] || echo --spatial-latent "$grid" ) "${readout[@]}" \
      --pixels 2048 --batch 8 --steps "$steps" --latent-dim "$dim" --seed 1 \
      --checkpoint-every 200 --json \
      $( [ -f "$model.bubble.ckpt" ] || [ -f "$model.gelslim.ckpt" ] && echo --resume ) |
    tee "$model.train.log" >&2
  tail -n 1 "$model.train.log" >"$model.train.json"
fi
for strategy in "${strategies[@]}"; do
  name="${tag}_d${dim}_s${steps}_${precision}_${strategy/:/_}"
  "$bin" encode --model "$model" --data "$out/data4242" --out "$out/$name.tfs" \
      --strategy "$strategy" --latent-precision "$precision" --json | tee "$out/$name.encode.log" >&2
  tail -n 1 "$out/$name.encode.log" >"$out/$name.encode.json"
  "$bin" eval --data "$out/data4242" --model "$model" --functaset "$out/$name.tfs" \
      --out "$out/eval_$name" >/dev/null
  python3 - "$out/eval_$name/table.json" "$strategy" "$precision" "$spec" "$dim" \
      "$model.train.json" "$out/$name.encode.json" <<'PY'
import json, sys
table = json.load(open(sys.argv[1]))
try:
    train = json.load(open(sys.argv[6]))["sensors"]
except (OSError, ValueError, KeyError):
    train = {}
try:
    rate = json.load(open(sys.argv[7]))["frames_per_s"]
except (OSError, ValueError, KeyError):
    rate = float("nan")
for sensor, t in table["targets"].items():
    n, a, s = t["psnr_3db_above_pca"], t["psnr_3db_above_pca_clean"], t["psnr_3db_above_pca_same_bits_clean"]
    seconds = train.get(sensor, {}).get("seconds", float("nan"))
    print(f"{sensor:8s} spatial {sys.argv[4]} d={sys.argv[5]} {sys.argv[3]} {sys.argv[2]}: "
          f"{a['bytes_per_frame']:.0f} B/frame | noisy: TactFunc {n['tactfunc_db']:.2f} dB, "
          f"PCA float32 {n['pca_db']:.2f} (margin {n['margin_db']:+.2f}) | noise-free: "
          f"TactFunc {a['tactfunc_db']:.2f} dB | PCA float32 {a['pca_db']:.2f} "
          f"(margin {a['margin_db']:+.2f}) | PCA same bits {s['pca_db']:.2f} "
          f"(margin {s['margin_db']:+.2f}) | train {seconds:.0f} s | encode {rate:.1f} "
          f"frames/s  [{sys.argv[1]}]")
PY
done
