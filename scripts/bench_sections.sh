#!/usr/bin/env bash
# The commands behind docs/BENCHMARKS.md's sections, on data this script makes, one after
# another in one process tree so that a run holds the machine alone: the simulator
# (`bench synth`), the latent-fitting strategies (`bench fit`, table and targets), the
# fitting kernels (`bench kernels`, Google Benchmark, on the committed small trunk and on
# the default-preset trunk), the FLANN indexes (`bench knn` on the functaset's two
# sensors, on 30,000 synthetic vectors and on a 30,000-frame Soft Bubble functaset),
# eval's PCA (`bench pca`), and the pose posteriors of docs/SAMPLERS.md (`bench
# posterior` with the committed small trunk and pose model). Each section's output goes
# to OUT/<section>.txt (tables as the docs quote them; the JSON line last) and is echoed.
# The PyTorch comparison has its own script (scripts/bench_peer.sh).
#
# Usage: scripts/bench_sections.sh OUT [SECTION ...]
#   SECTION: synth fit kernels knn knn30k pca posterior (default: all of them)
# Data (made once in OUT and reused): OUT/data = `synth --frames-per-tool 150 --seed 1
# --clean` (both sensors; 1,620 train and 180 test frames each), for knn30k OUT/data30k =
# `synth --frames-per-tool 2500 --seed 3 --sensors bubble`, for posterior OUT/pfresh =
# `synth --frames-per-tool 200 --sensors bubble --seed 11`, each encoded with the
# committed models/pretrained/default.tfm into OUT/<name>.tfs.
# About 12 minutes on 2 idle cores, of which knn30k's data takes 2.5, pca 1 and posterior 1.
# TACTFUNC picks the binary (default build/bin/tactfunc, built if missing).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ $# -lt 1 ]; then
  sed -n '2,21p' "$0" | sed 's/^# \{0,1\}//'
  exit 2
fi
out=$1
shift
sections=("$@")
[ ${#sections[@]} -gt 0 ] || sections=(synth fit kernels knn knn30k pca posterior)
for s in "${sections[@]}"; do
  case "$s" in
    synth | fit | kernels | knn | knn30k | pca | posterior) ;;
    *)
      echo "bench_sections.sh: unknown section '$s'" \
        "(expected synth, fit, kernels, knn, knn30k, pca or posterior)" >&2
      exit 2
      ;;
  esac
done
TF=${TACTFUNC:-build/bin/tactfunc}
test -x "$TF" || bash scripts/build.sh
mkdir -p "$out"
model=models/pretrained/default.tfm

run() { echo "+ $*"; "$@"; }
section() {  # section NAME COMMAND...: runs it, its output to OUT/NAME.txt and the terminal
  local name=$1
  shift
  local when load
  when=$(date -u '+%Y-%m-%d %H:%M UTC')
  load=$(cut -d' ' -f1-3 /proc/loadavg)
  echo "== $name ($when, load average $load)" | tee "$out/$name.txt"
  "$@" 2>&1 | tee -a "$out/$name.txt"
}
encoded() {  # encoded NAME SYNTH_FLAGS...: OUT/NAME synthesised and encoded, once
  local name=$1
  shift
  if [ ! -f "$out/$name.tfs" ]; then
    run "$TF" synth --out "$out/$name" "$@" --overwrite
    run "$TF" encode --model "$model" --data "$out/$name" --out "$out/$name.tfs"
  fi
}
shared_data() { encoded data --frames-per-tool 150 --seed 1 --clean; }  # fit's and knn's

for s in "${sections[@]}"; do
  case "$s" in
    synth) section synth "$TF" bench synth --json ;;
    fit)
      shared_data
      section fit "$TF" bench fit --model "$model" --functaset "$out/data.tfs" --data "$out/data" \
        --threads 1 --frames 20 --plot "$out/bench_fit_pareto.png" --json
      ;;
    kernels)
      section kernels_small "$TF" bench kernels --model "$model" --json
      section kernels_default "$TF" bench kernels --json
      ;;
    knn)
      shared_data
      section knn_bubble "$TF" bench knn --functaset "$out/data.tfs" --sensor bubble --json
      section knn_gelslim "$TF" bench knn --functaset "$out/data.tfs" --sensor gelslim --json
      section knn_synthetic "$TF" bench knn --synthetic 30000 --json
      ;;
    knn30k)
      encoded data30k --frames-per-tool 2500 --seed 3 --sensors bubble
      section knn30k "$TF" bench knn --functaset "$out/data30k.tfs" --sensor bubble --json
      ;;
    pca) section pca "$TF" bench pca --reference --exact ;;
    posterior)
      encoded pfresh --frames-per-tool 200 --sensors bubble --seed 11
      section posterior "$TF" bench posterior --model "$model" \
        --pose-model models/pretrained/pose_bubble.tpm --functaset "$out/pfresh.tfs" \
        --data "$out/pfresh" --frames 60 --samplers laplace,sgld,knn --json
      ;;
  esac
done
echo "bench_sections.sh: outputs in $out"
