#!/usr/bin/env bash
# A photometric model on recordings whose references differ from the one it was trained
# on: two simulated GelSlim recordings of the same contacts, one with the training
# data's marker darkness (0.7) and one with lighter markers (0.3), each with its own
# reference; then both as one set of clips. Prints each encode's mean PSNR and writes
# the light recording's reconstructions (OUT/recon_light/recon_gelslim.png).
#   usage: scripts/photometric_own_reference.sh MODEL OUT [BIN]
# MODEL: a `train --head photometric` model of GelSlim frames (docs/REPRESENTATION.md).
# BIN (default build/bin/tactfunc): another build's binary runs the same commands, e.g.
# one from before frames were drawn against their own reference.
set -euo pipefail
export LC_ALL=C
cd "$(dirname "$0")/.."
model=${1:?usage: $0 MODEL OUT [BIN]}
out=${2:?usage: $0 MODEL OUT [BIN]}
bin=${3:-build/bin/tactfunc}
rm -rf "$out"
mkdir -p "$out/clips/dark" "$out/clips/light"
for darkness in 0.7 0.3; do
  name=$([ "$darkness" = 0.7 ] && echo dark || echo light)
  "$bin" synth --out "$out/$name" --frames-per-tool 15 --sensors gelslim --seed 5151 \
    --gelslim-marker-darkness "$darkness" >/dev/null 2>&1
  cp "$out/$name"/gelslim/*.png "$out/clips/$name/"
done
for data in dark light clips; do
  "$bin" encode --data "$out/$data" --model "$model" --out "$out/$data.tfs" --threads 2 \
    --allow-other-frames >"$out/encode_$data.log" 2>&1 || { cat "$out/encode_$data.log"; exit 1; }
  echo "$data: $(grep 'mean PSNR' "$out/encode_$data.log" | sed 's/^ *//')"
done
"$bin" recon --data "$out/light" --model "$model" --functaset "$out/light.tfs" \
  --out "$out/recon_light" --examples 3 --threads 2 --allow-other-frames >/dev/null
echo "pictures: $out/recon_light/recon_gelslim.png"
