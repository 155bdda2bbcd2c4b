#!/usr/bin/env bash
# The Soft Bubble readout trunk of docs/REPRESENTATION.md, "Sharing the bytes among the
# latent's values": trained on whole frames against their noise-free copies, every fit
# its projection shrunk by Wiener gains (--outer-clean --inner-steps 0), d = 256, then
# encoded in allocated codes of B bytes per frame (`encode --latent-bytes B`) on fresh
# sets no training used and scored by `eval` against PCA codes in the same bytes through
# the same allocation (the component count that serves PCA best), noise-free frames.
#
#   bash scripts/representation_allocated_codes.sh [OUT_DIR] [FRAMES_PER_TOOL] [BYTES...]
#
# Defaults: /tmp/tactfunc_allocated, 1500 training contacts per tool (16,200 train frames;
# 150 gives the 1,620 of a default dataset's split), B = 128 256. Training data: synth
# seed 5151; fresh sets: seeds 4242, 777, 2024 and 31337, 150 contacts per tool each. Training
# takes about 2 minutes on one core at 1500 contacts per tool (the basis from 5,000 of the
# copies), 45 s at 150. Every figure printed comes from the eval table.json named on its
# line. Last, the trade in a picture: the first fresh set at 32, 64, 128 and 256 B per
# frame, against PCA codes in the same bytes (OUT/eval_rate_distortion/rate_distortion.png).
# MODEL=M scores the trunk M instead of training one (e.g. the committed
# models/pretrained/bubble_readout.tfm; FRAMES_PER_TOOL then only names the outputs).
# SEEDS="S1 S2 ..." scores other fresh sets (the picture is of the first). SENSOR=gelslim
# scores a GelSlim trunk instead (MODEL required; fresh sets of that sensor), and MODEL_B=M
# scores budget B with the trunk M (e.g. the GelSlim's two committed trunks:
# SENSOR=gelslim MODEL=models/pretrained/gelslim.tfm
# MODEL_256=models/pretrained/gelslim_256.tfm). THREADS=T encodes and scores on T threads
# (default 1).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-/tmp/tactfunc_allocated}
per_tool=${2:-1500}
shift $(( $# < 2 ? $# : 2 ))
bytes=("$@")
[ ${#bytes[@]} -gt 0 ] || bytes=(128 256)
bin=build/bin/tactfunc
sensor=${SENSOR:-bubble}
threads=${THREADS:-1}
[ -x "$bin" ] || { echo "representation_allocated_codes: build first (bash scripts/build.sh)" >&2; exit 1; }
mkdir -p "$out"
synth() {  # synth DIR SEED PER_TOOL
  [ -f "$1/dataset.json" ] ||
    "$bin" synth --out "$1" --frames-per-tool "$3" --seed "$2" --clean --sensors "$sensor" \
        >/dev/null
}
if [ -n "${MODEL:-}" ] && [ ! -f "$MODEL" ]; then
  echo "representation_allocated_codes: MODEL=$MODEL: no such file" >&2; exit 1
fi
if [ "$sensor" != bubble ] && [ -z "${MODEL:-}" ]; then
  echo "representation_allocated_codes: SENSOR=$sensor needs MODEL=M (it trains the Soft" \
       "Bubble's trunk only)" >&2; exit 1
fi
model=${MODEL:-$out/readout_d256_t$per_tool.tfm}
model_for() {  # the trunk that scores budget $1: MODEL_$1 if set, else the model
  local name="MODEL_$1"
  echo "${!name:-$model}"
}
if [ ! -f "$model" ]; then
  synth "$out/train$per_tool" 5151 "$per_tool"
  pca_frames=()
  [ "$per_tool" -le 150 ] || pca_frames=(--readout-pca-frames 5000)
  "$bin" train --data "$out/train$per_tool" --out "$model" --preset small --readout \
      "${pca_frames[@]}" --pixels 0 --batch 8 --steps 1000 --latent-dim 256 --seed 1 \
      --sensors bubble --threads 1 --outer-clean --inner-steps 0 >&2
fi
read -r -a seeds <<< "${SEEDS:-4242 777 2024 31337}"
for seed in "${seeds[@]}"; do
  synth "$out/fresh$seed" "$seed" 150
  for b in "${bytes[@]}"; do
    name="t${per_tool}_s${seed}_b$b"
    m=$(model_for "$b")
    "$bin" encode --model "$m" --data "$out/fresh$seed" --out "$out/$name.tfs" \
        --latent-bytes "$b" --sensors "$sensor" --threads "$threads" >&2
    "$bin" eval --model "$m" --data "$out/fresh$seed" --functaset "$out/$name.tfs" \
        --out "$out/eval_$name" --threads "$threads" >/dev/null 2>&1
    python3 - "$out/eval_$name/table.json" "$seed" "$b" "$sensor" <<'PY'
import json, sys
path, seed, b, sensor = sys.argv[1:]
t = json.load(open(path))["targets"][sensor]["psnr_3db_above_pca_same_bits_clean"]
print(f"seed {seed}, {b} B per frame: TactFunc {t['tactfunc_db']:.2f} dB, PCA codes in the same "
      f"bytes {t['pca_db']:.2f} dB ({t['pca_components']} components), margin "
      f"{t['margin_db']:+.2f} dB, {'met' if t['met'] else 'NOT met'}  ({path})")
PY
  done
done
first=${seeds[0]}
name="t${per_tool}_s$first"
for b in 32 64 128 256; do
  [ -f "$out/${name}_b$b.tfs" ] ||
    "$bin" encode --model "$(model_for "$b")" --data "$out/fresh$first" \
        --out "$out/${name}_b$b.tfs" --latent-bytes "$b" --sensors "$sensor" \
        --threads "$threads" >&2
done
extras=()
for b in 32 64 256; do
  extras+=(--extra-functaset "$out/${name}_b$b.tfs" --extra-model "$(model_for "$b")")
done
"$bin" eval --model "$(model_for 128)" --data "$out/fresh$first" \
    --functaset "$out/${name}_b128.tfs" "${extras[@]}" --out "$out/eval_rate_distortion" \
    --threads "$threads" >/dev/null 2>&1
echo "picture: $out/eval_rate_distortion/rate_distortion.png"
