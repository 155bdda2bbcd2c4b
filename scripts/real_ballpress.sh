#!/usr/bin/env bash
# The real GelSight ball presses (tests/data/taxim_ballpress) through train, encode, recon
# and eval: PSNR of the functaset against PCA at equal bytes on the unseen presses, and
# how far the contact centres of the raw frames and of the reconstructions fall from the
# hand-placed ones (median and 90th percentile, pixels).
#   usage: scripts/real_ballpress.sh OUT [LATENT_DIM] [STEPS] [STRATEGY] [HEAD] [LIGHTING]
#                                     [LATENT_BYTES] [LATENT_NOISE]
# Defaults: d = 16, 2000 steps, meta_sgd:3, HEAD direct (trunk: --preset small --readout).
# HEAD photometric trains `--head photometric --preset small` instead (the SIREN draws
# the contact, a head shades it; fit it with STRATEGY adam:N, the default adam:200);
# HEAD photometric-background also stores the sensor's background (`train --background`).
# LIGHTING K > 0 adds K lighting images (`train --lighting K`, photometric heads only).
# LATENT_BYTES B stores each latent in B bytes (`encode --latent-bytes B`; default: float16,
# 2 d bytes). LATENT_NOISE S > 0 trains with noise S on the latents' code values
# (`train --latent-noise S`, photometric heads only). The environment's SEED (default 1)
# seeds the training. With VALIDATION=1 in the environment the 12 test presses are left
# out and every fifth training press (7 of 37) is held out as the test split instead
# (a copy of the fixture under OUT/validation_data): for choosing settings without
# looking at the test presses.
set -euo pipefail
export LC_ALL=C
cd "$(dirname "$0")/.."
out=${1:?usage: $0 OUT [LATENT_DIM] [STEPS] [STRATEGY] [HEAD] [LIGHTING] [LATENT_BYTES] [NOISE]}
dim=${2:-16}
steps=${3:-2000}
strategy=${4:-meta_sgd:3}
head=${5:-direct}
lighting=${6:-0}
latent_bytes=${7:-}
latent_noise=${8:-0}
case "$head" in
  direct) trunk_flags=(--preset small --readout) ;;
  photometric) trunk_flags=(--head photometric --preset small) ;;
  photometric-background) trunk_flags=(--head photometric --preset small --background) ;;
  *) echo "$0: HEAD must be direct, photometric or photometric-background, got '$head'" >&2
     exit 2 ;;
esac
if [ "$lighting" != 0 ]; then
  case "$head" in
    photometric*) trunk_flags+=(--lighting "$lighting") ;;
    *) echo "$0: LIGHTING needs a photometric HEAD" >&2; exit 2 ;;
  esac
fi
if [ "$latent_noise" != 0 ]; then
  case "$head" in
    photometric*) trunk_flags+=(--latent-noise "$latent_noise") ;;
    *) echo "$0: LATENT_NOISE needs a photometric HEAD" >&2; exit 2 ;;
  esac
fi
encode_flags=()
[ -n "$latent_bytes" ] && encode_flags=(--latent-bytes "$latent_bytes")
bin=build/bin/tactfunc
data=tests/data/taxim_ballpress
rm -rf "$out"
mkdir -p "$out"
if [ "${VALIDATION:-0}" = 1 ]; then
  held="$out/validation_data"
  mkdir -p "$held"
  cp "$data"/{LICENSE,README.md,contacts.csv,reference.png} "$held/"
  awk -F, 'NR == 1 { print; next }
           $8 == "train" { if (++n % 5 == 0) sub(/train$/, "test"); print }' \
    "$data/labels.csv" >"$held/labels.csv"
  for frame in $(awk -F, 'NR > 1 { print $1 }' "$held/labels.csv"); do
    cp "$data/$frame.png" "$held/"
  done
  data=$held
fi
$bin train --data "$data" --out "$out/m.tfm" "${trunk_flags[@]}" --latent-dim "$dim" \
  --steps "$steps" --seed "${SEED:-1}" >"$out/train.log" 2>&1 || { cat "$out/train.log"; exit 1; }
$bin encode --data "$data" --model "$out/m.tfm" --out "$out/f.tfs" --strategy "$strategy" \
  "${encode_flags[@]}" >"$out/encode.log" 2>&1 || { cat "$out/encode.log"; exit 1; }
$bin recon --data "$data" --model "$out/m.tfm" --functaset "$out/f.tfs" --out "$out/recon" \
  --examples 6 >"$out/recon.log"
$bin eval --data "$data" --model "$out/m.tfm" --functaset "$out/f.tfs" --out "$out/eval" \
  --json >"$out/eval.log" 2>&1
echo "real GelSight presses: $head trunk, d = $dim, $steps steps, $strategy," \
  "$lighting lighting images, ${latent_bytes:-float16 (2 d)} bytes a latent," \
  "latent noise $latent_noise, seed ${SEED:-1}$([ "${VALIDATION:-0}" = 1 ] &&
  echo ", validation split: 30 training presses, 7 held out as test")"
grep -A3 '^sensor   split   contact' "$out/recon.log"
# Centre errors: frames.csv columns 15-18 (contact_row/col, recon_contact_row/col) against
# contacts.csv (x = column, y = row), per split.
errors=$(join -t, <(tail -n +2 "$out/recon/frames.csv" | sort) \
  <(tail -n +2 "$data/contacts.csv" | sort) |
  awk -F, '{ print $3, sqrt(($16-$19)^2 + ($15-$20)^2), sqrt(($18-$19)^2 + ($17-$20)^2) }')
percentiles() {  # stdin: numbers; prints the median and the 90th percentile
  sort -g | awk '{ v[NR] = $1 } END { printf "median %.1f p90 %.1f", v[int((NR - 1) * 0.5) + 1], v[int((NR - 1) * 0.9) + 1] }'
}
for split in train test; do
  n=$(awk -v s="$split" '$1 == s' <<<"$errors" | wc -l)
  raw=$(awk -v s="$split" '$1 == s { print $2 }' <<<"$errors" | percentiles)
  rec=$(awk -v s="$split" '$1 == s { print $3 }' <<<"$errors" | percentiles)
  echo "$split: $n presses, contact centre error (px): raw frame $raw; reconstruction $rec"
done
grep -E '^\| (TactFunc|PCA)' "$out/eval/table.md" | head -8 || true
echo "pictures: $out/recon/recon_gelslim.png, $out/eval/rate_distortion.png"
