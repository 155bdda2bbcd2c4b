#!/usr/bin/env bash
# The trunk-size sweep of docs/RESULTS_RECONSTRUCTION.md ("model only what a scene
# requires"): for each sensor:width:layers:latent_dim in CONFIGS, train a trunk for STEPS
# outer steps on one dataset, encode every frame (K meta-SGD steps), reconstruct, and
# record test PSNR (vs noisy and clean), encoding rate (frames/s on THREADS threads, i.e.
# the fit time per frame), training time and bytes. Every run has the same seed, data and
# budget, so the columns compare sizes at equal training steps, not converged models.
#
#   WORK=/tmp/sweep STEPS=1000 bash scripts/sweep_trunk.sh
#   CONFIGS="bubble:64:3:32 gelslim:128:3:64" bash scripts/sweep_trunk.sh
#
# Output: $WORK/sweep.jsonl (one line per run) and $WORK/sweep.md (a markdown table).
# Needs jq for the table. Reruns skip finished configurations (delete $WORK/runs/<cfg>),
# and reuse a run's trained model and functaset when only its result.json is deleted.
set -euo pipefail
cd "$(dirname "$0")/.."
WORK=${WORK:-/tmp/tactfunc_sweep}
STEPS=${STEPS:-1000}
THREADS=${THREADS:-0}
FRAMES_PER_TOOL=${FRAMES_PER_TOOL:-150}
DATA=${DATA:-$WORK/data}
CONFIGS=${CONFIGS:-"bubble:32:3:32 bubble:64:3:16 bubble:64:3:32 bubble:64:3:64 bubble:64:3:128 bubble:128:3:64 gelslim:32:3:64 gelslim:64:3:64 gelslim:64:3:128 gelslim:128:3:64 gelslim:64:6:64"}
TF=build/bin/tactfunc
test -x "$TF" || bash scripts/build.sh
command -v jq >/dev/null || apt-get install -y -qq jq
mkdir -p "$WORK/runs"

if [ ! -f "$DATA/dataset.json" ]; then
  echo "+ $TF synth --out $DATA --frames-per-tool $FRAMES_PER_TOOL --seed 1 --clean"
  "$TF" synth --out "$DATA" --frames-per-tool "$FRAMES_PER_TOOL" --seed 1 --clean --overwrite
fi

for cfg in $CONFIGS; do
  IFS=: read -r sensor width layers dim <<<"$cfg"
  run="$WORK/runs/${sensor}_w${width}_l${layers}_d${dim}"
  if [ -f "$run/result.json" ]; then echo "sweep: $cfg done earlier"; continue; fi
  mkdir -p "$run"
  if [ ! -f "$run/m.tfm" ]; then
    echo "+ train $cfg ($STEPS steps)"
    "$TF" train --data "$DATA" --out "$run/m.tfm" --sensors "$sensor" --preset small \
      --width "$width" --layers "$layers" --latent-dim "$dim" --pixels 512 --batch 32 \
      --steps "$STEPS" --seed 1 --threads "$THREADS" --checkpoint-every 0 --json \
      > "$run/train.log" 2>&1
  fi
  if [ ! -f "$run/f.tfs" ]; then
    "$TF" encode --model "$run/m.tfm" --data "$DATA" --out "$run/f.tfs" --sensors "$sensor" \
      --threads "$THREADS" --json > "$run/encode.log" 2>&1
  fi
  "$TF" recon --model "$run/m.tfm" --functaset "$run/f.tfs" --data "$DATA" --out "$run/recon" \
    --examples 4 --json > "$run/recon.log" 2>&1
  rm -f "$run"/m.tfm.*.ckpt
  jq -c --arg s "$sensor" --argjson w "$width" --argjson l "$layers" --argjson d "$dim" \
    --argjson steps "$STEPS" \
    --slurpfile t <(tail -n 1 "$run/train.log") --slurpfile e <(tail -n 1 "$run/encode.log") \
    '{sensor: $s, width: $w, layers: $l, latent_dim: $d, steps: $steps,
      parameters: $t[0].sensors[$s].parameters, train_seconds: $t[0].sensors[$s].seconds,
      psnr_test: .psnr_test[$s], psnr_test_clean: (.psnr_test_clean // {})[$s],
      psnr_test_source_peak: .psnr_test_source_peak[$s],
      psnr_train: .psnr_train[$s], encode_frames_per_s: $e[0].frames_per_s,
      threads: $e[0].threads, model_bytes: .model_bytes, latent_bytes: .latent_bytes,
      compression_ratio: .compression_ratio}' <(tail -n 1 "$run/recon.log") > "$run/result.json"
  cat "$run/result.json"
done

cat "$WORK"/runs/*/result.json > "$WORK/sweep.jsonl"
{
  echo "| sensor | width x layers | d | parameters | test PSNR noisy / clean (dB) | paper convention (dB) | train PSNR (dB) | encode frames/s | ms per frame | train s | compression |"
  echo "|---|---|---|---|---|---|---|---|---|---|---|"
  jq -s -r 'sort_by(.sensor, .width, .layers, .latent_dim)[] | "| \(.sensor) | \(.width) x \(.layers) | \(.latent_dim) | \(.parameters) | \(.psnr_test*100|round/100) / \((.psnr_test_clean // 0)*100|round/100) | \((.psnr_test_source_peak // 0)*100|round/100) | \(.psnr_train*100|round/100) | \(.encode_frames_per_s*10|round/10) | \(1000*.threads/.encode_frames_per_s*100|round/100) | \(.train_seconds|round) | \(.compression_ratio|round)x |"' \
    "$WORK/sweep.jsonl"
} > "$WORK/sweep.md"
cat "$WORK/sweep.md"
