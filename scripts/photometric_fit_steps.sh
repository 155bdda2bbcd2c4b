#!/usr/bin/env bash
# How many Adam steps the warm-started photometric fit can take by default
# (docs/REPRESENTATION.md, "The warm-started fit's steps re-picked"): `encode` of a
# selection set no training used with the committed GelSlim trunk and `--strategy
# knn+adam:N` for each N, the N alternated over ROUNDS rounds (this machine is shared
# and noisy: the rate is the median over the rounds, with its range), then each N's
# functaset of the last round scored by `recon` (test split: mean PSNR against the
# noisy and the noise-free frames, and in the paper's convention).
#
#   bash scripts/photometric_fit_steps.sh [OUT_DIR] [ROUNDS] [N...]
#
# Defaults: /tmp/tactfunc_fit_steps, 3 rounds, N = 20 80 100 120 140 160 (the default,
# 140, and the count above it). The selection set is `synth --frames-per-tool 150
# --sensors gelslim --seed 777 --clean` (1,800 frames; the evaluation set of the docs is
# seed 4242). MODEL=M scores another photometric trunk. Takes about 7 minutes on 2 cores
# with the defaults. Run it on an otherwise idle machine:
# a second job halves the rates.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-/tmp/tactfunc_fit_steps}
rounds=${2:-3}
shift $(( $# < 2 ? $# : 2 ))
steps=("$@")
[ ${#steps[@]} -gt 0 ] || steps=(20 80 100 120 140 160)
bin=build/bin/tactfunc
model=${MODEL:-models/pretrained/gelslim.tfm}
[ -x "$bin" ] || { echo "photometric_fit_steps: build first (bash scripts/build.sh)" >&2; exit 1; }
[ -f "$model" ] || { echo "photometric_fit_steps: MODEL=$model: no such file" >&2; exit 1; }
command -v python3 >/dev/null || { echo "photometric_fit_steps: needs python3" >&2; exit 1; }
mkdir -p "$out"
data=$out/select777
[ -f "$data/dataset.json" ] ||
  "$bin" synth --out "$data" --frames-per-tool 150 --sensors gelslim --seed 777 --clean >/dev/null
rates=$out/rates.txt
: > "$rates"
for round in $(seq 1 "$rounds"); do
  for n in "${steps[@]}"; do
    rm -f "$out/steps$n.tfs"
    "$bin" encode --model "$model" --data "$data" --sensors gelslim --threads 2 \
        --out "$out/steps$n.tfs" --strategy "knn+adam:$n" --json 2>/dev/null |
      tail -1 | python3 -c "import json, sys; print($n, json.load(sys.stdin)['frames_per_s'])" \
      >> "$rates"
    echo "photometric_fit_steps: round $round/$rounds, knn+adam:$n: $(tail -1 "$rates" |
      cut -d' ' -f2) frames/s" >&2
  done
done
for n in "${steps[@]}"; do
  rm -rf "$out/recon$n"
  "$bin" recon --model "$model" --functaset "$out/steps$n.tfs" --data "$data" \
      --out "$out/recon$n" --examples 0 --threads 2 --json 2>/dev/null | tail -1 > "$out/recon$n.json"
done
python3 - "$out" "$rates" "${steps[@]}" <<'EOF'
import json, statistics, sys
out, rates, steps = sys.argv[1], sys.argv[2], [int(s) for s in sys.argv[3:]]
by = {}
for line in open(rates):
    n, r = line.split()
    by.setdefault(int(n), []).append(float(r))
print("| fit | frames/s on 2 threads, median (range) | test PSNR noisy | noise-free "
      "| paper's convention |")
print("|---|---:|---:|---:|---:|")
for n in steps:
    r = by[n]
    j = json.load(open(f"{out}/recon{n}.json"))
    print(f"| knn+adam:{n} | {statistics.median(r):.1f} ({min(r):.1f}-{max(r):.1f}) | "
          f"{j['psnr_test']['gelslim']:.2f} | {j['psnr_test_clean']['gelslim']:.2f} | "
          f"{j['psnr_test_source_peak']['gelslim']:.2f} |")
EOF
