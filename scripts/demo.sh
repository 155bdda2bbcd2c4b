#!/usr/bin/env bash
# The demo: a small paired Soft Bubble + GelSlim dataset from the simulator, its summary,
# and a contact sheet with the tools' poses drawn on the frames.
set -euo pipefail
cd "$(dirname "$0")/.."
TF=build/bin/tactfunc
OUT=demo
mkdir -p "$OUT"
echo "== synthesize 12 tools x 10 paired frames"
"$TF" synth --out "$OUT/data" --frames-per-tool 10 --seed 7 --overwrite
echo "== dataset summary"
"$TF" info "$OUT/data"
echo "== contact sheet"
"$TF" show "$OUT/data" --out "$OUT/contact_sheet.png"
echo "demo: done. Look at $OUT/contact_sheet.png"
