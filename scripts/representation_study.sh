#!/usr/bin/env bash
# The representation study's rows that need no training (docs/REPRESENTATION.md): the
# committed trunk's global latent encoded two ways -- its own meta-SGD steps and fitted to
# convergence (ceres:N) -- against PCA at equal bytes per frame, on fresh simulated
# contacts with noise-free copies, both sensors, test split.
#
#   bash scripts/representation_study.sh [OUT_DIR] [FRAMES_PER_TOOL] [SEED] [CERES_ITERATIONS]
#
# Defaults: /tmp/tactfunc_representation, 20 frames per tool, seed 4242 (no training run
# used it), ceres:20. Prints one line per encoding and sensor; every figure comes from
# the eval table.json it names.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-/tmp/tactfunc_representation}
frames=${2:-20}
seed=${3:-4242}
iterations=${4:-20}
bin=build/bin/tactfunc
model=models/pretrained/default.tfm
pose=models/pretrained/pose_bubble.tpm
[ -x "$bin" ] || { echo "representation_study: build first (bash scripts/build.sh)" >&2; exit 1; }
mkdir -p "$out"
if [ ! -f "$out/data/dataset.json" ]; then
  "$bin" synth --out "$out/data" --frames-per-tool "$frames" --seed "$seed" --clean >/dev/null
fi
for strategy in default "ceres:$iterations"; do
  name=${strategy/:/_}
  flag=()
  [ "$strategy" = default ] || flag=(--strategy "$strategy")
  start=$(date +%s.%N)
  "$bin" encode --model "$model" --data "$out/data" --out "$out/$name.tfs" "${flag[@]}" \
      --json >"$out/$name.encode.json"
  "$bin" eval --data "$out/data" --model "$model" --functaset "$out/$name.tfs" \
      --pose-model "$pose" --out "$out/eval_$name" >/dev/null
  python3 - "$out/eval_$name/table.json" "$out/$name.encode.json" <<'PY'
import json, sys
table = json.load(open(sys.argv[1]))
encode = json.loads(open(sys.argv[2]).read().strip().splitlines()[-1])
for sensor, t in table["targets"].items():
    a, c = t["psnr_3db_above_pca"], t["psnr_3db_above_pca_clean"]
    strategy = table["details"][sensor]["fit_strategy"]
    print(f"{sensor:8s} {strategy:11s} {a['bytes_per_frame']:.0f} B/frame: "
          f"TactFunc {a['tactfunc_db']:.2f} dB vs PCA {a['pca_db']:.2f} (noisy frames, "
          f"margin {a['margin_db']:+.2f}); noise-free {c['tactfunc_db']:.2f} vs {c['pca_db']:.2f} "
          f"(margin {c['margin_db']:+.2f}); encode {encode['frames_per_s']:.1f} frames/s "
          f"on {encode['threads']} threads  [{sys.argv[1]}]")
PY
done
