#!/usr/bin/env bash
# The demo (README command 1 ends here): a small paired Soft Bubble + GelSlim dataset
# from the simulator and its contact sheet; then, with the committed pretrained trunks
# (the Soft Bubble's in models/pretrained/bubble.tfm, d = 128 stored as 8-bit codes,
# reproducible with scripts/train_pretrained_bubble.sh; the GelSlim's photometric trunk in
# models/pretrained/gelslim.tfm, scripts/train_pretrained_gelslim.sh), the functasets of
# the dataset and their reconstructions, 128 B per frame each; then one frame's pose
# posterior by both paths: the committed pose model on the frame's latent under the small
# two-sensor trunk it was trained on (models/pretrained/pose_bubble.tpm on
# models/pretrained/default.tfm; scripts/train_pretrained_pose.sh, scripts/train_pretrained.sh)
# and the pose fitted through the committed generator
# (models/pretrained/pose_generator_bubble.tpg, scripts/train_pretrained_generator.sh)
# rendering through the Soft Bubble trunk above (--generator-model). Step 4 also shows the
# Soft Bubble's storage trunk (models/pretrained/bubble_readout.tfm,
# scripts/train_pretrained_bubble_readout.sh) at the same 128 B per frame, its bytes shared
# among its 256 values (encode --latent-bytes 128).
# Everything lands in demo/.
set -euo pipefail
cd "$(dirname "$0")/.."
TF=build/bin/tactfunc
OUT=demo
BUBBLE_MODEL=models/pretrained/bubble.tfm
GELSLIM_MODEL=models/pretrained/gelslim.tfm
STORAGE_MODEL=models/pretrained/bubble_readout.tfm
POSE_TRUNK=models/pretrained/default.tfm
mkdir -p "$OUT"
echo "== 1. synthesize 12 tools x 10 paired contacts (Soft Bubble + GelSlim, known SE(2) poses)"
"$TF" synth --out "$OUT/data" --frames-per-tool 10 --seed 7 --clean --overwrite
"$TF" info "$OUT/data"
echo "== 2. contact sheet: raw | reference | difference, pose arrows"
"$TF" show "$OUT/data" --out "$OUT/contact_sheet.png"
echo "== 3. encode every frame as one latent under the pretrained trunks (the functasets)"
"$TF" encode --model "$BUBBLE_MODEL" --data "$OUT/data" --sensors bubble --latent-precision uint8 \
  --out "$OUT/functaset.tfs"
"$TF" encode --model "$GELSLIM_MODEL" --data "$OUT/data" --sensors gelslim \
  --out "$OUT/functaset_gelslim.tfs"
echo "== 4. reconstruct from the latents: PSNR, size, pictures"
"$TF" recon --model "$BUBBLE_MODEL" --functaset "$OUT/functaset.tfs" --data "$OUT/data" \
  --out "$OUT/recon/bubble" --examples 6
"$TF" recon --model "$GELSLIM_MODEL" --functaset "$OUT/functaset_gelslim.tfs" \
  --data "$OUT/data" --out "$OUT/recon/gelslim" --examples 6
echo "   the Soft Bubble storage trunk at the same 128 B per frame, its bytes shared among 256 values"
"$TF" encode --model "$STORAGE_MODEL" --data "$OUT/data" --sensors bubble --latent-bytes 128 \
  --out "$OUT/functaset_storage.tfs"
"$TF" recon --model "$STORAGE_MODEL" --functaset "$OUT/functaset_storage.tfs" \
  --data "$OUT/data" --out "$OUT/recon/bubble_storage" --examples 6
echo "== 5. one frame in, pose posterior out: sgld samples through the pretrained pose MLP (latent"
echo "      path), then the pose fitted through the pretrained generator and the trunk (generator path)"
# A test-split frame of the rod (frames 000000.. are listed tool by tool; see labels.csv).
ID=$(awk -F, '$2 == "bubble" && $8 == "test" { if (!any) any = $1; if ($3 == "rod") { print $1; found = 1; exit } }
              END { if (!found) print any }' "$OUT/data/labels.csv")
"$TF" pose --model "$POSE_TRUNK" --pose-model models/pretrained/pose_bubble.tpm --data "$OUT/data" \
  --id "$ID" --sampler sgld --samples 100 --method both \
  --generator models/pretrained/pose_generator_bubble.tpg --generator-model "$BUBBLE_MODEL" \
  --out "$OUT/pose"
echo "demo: done. Look at $OUT/contact_sheet.png, $OUT/recon/*/recon_*.png and $OUT/pose/posterior.png"
