#!/usr/bin/env bash
# tactfunc against PyTorch on the CPU, side by side: the same trunk workloads timed by
# `tactfunc bench trunk` and by scripts/peer/torch_trunk.py (a PyTorch implementation
# of the same latent-modulated SIREN, meta-SGD fit and second-order meta-training step),
# one thread each, run INTERLEAVED (tactfunc, PyTorch, tactfunc, PyTorch, ... one pair
# per round and trunk size) so that a shared, noisy machine slows both alike. For each
# size it prints the median over rounds of the ratio PyTorch time / tactfunc time, and
# its min-max range, for: the fit's K steps ("fit core"), the whole fit ("full fit") and
# one meta-training step. Ratios above 1 mean tactfunc is faster. docs/BENCHMARKS.md
# ("Against PyTorch on the CPU") quotes its output.
#
# Usage: scripts/bench_peer.sh [--rounds N] [--repeats N] [--meta-repeats N]
#                              [--sizes W:L:D,...] [--out DIR]
#                              [--products float|bf16] [--peer-products float|bf16]
#   --rounds        interleaved rounds (default 5)
#   --repeats       timed fits per program run (default 10)
#   --meta-repeats  timed meta-training steps per program run (default 3)
#   --sizes         trunk sizes width:layers:latent (default 64:3:64,128:4:128,256:6:256)
#   --out           keep every JSON line here (default: a temporary folder)
#   --products      precision of tactfunc's matrix products (bench trunk --products;
#                   default float)
#   --peer-products precision of the peer's (bf16: torch.autocast; default: --products)
# The frame is 70x88 (the bubble's working resolution), K = 3, and a meta-training step
# is 32 frames x 512 random pixels (the presets' batch), float32 everywhere but the
# products under --products / --peer-products bf16.
#
# PyTorch is not a dependency of tactfunc: without an importable torch this prints how
# to install it and exits 0 ("skipped"). Debian: apt-get install -y python3-torch, and
# for a fast BLAS apt-get install -y libopenblas0-pthread (then update-alternatives
# --config libblas.so.3-x86_64-linux-gnu, or LD_LIBRARY_PATH as below). When OpenBLAS is
# installed this script puts /usr/lib/x86_64-linux-gnu/openblas-pthread first on
# LD_LIBRARY_PATH and reports the BLAS libraries the PyTorch process mapped.
# PYTHON=/path/to/python picks the interpreter; TACTFUNC the tactfunc binary.
set -euo pipefail
cd "$(dirname "$0")/.."

rounds=5
repeats=10
meta_repeats=3
sizes="64:3:64,128:4:128,256:6:256"
out=""
products=float
peer_products=""
while [[ $# -gt 0 ]]; do
  case "$1" in
    --rounds) rounds="$2"; shift 2 ;;
    --repeats) repeats="$2"; shift 2 ;;
    --meta-repeats) meta_repeats="$2"; shift 2 ;;
    --sizes) sizes="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    --products) products="$2"; shift 2 ;;
    --peer-products) peer_products="$2"; shift 2 ;;
    -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) echo "bench_peer: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done

peer_products="${peer_products:-$products}"
for p in "$products" "$peer_products"; do
  if [[ "$p" != float && "$p" != bf16 ]]; then
    echo "bench_peer: --products / --peer-products: expected float or bf16, got '$p'" >&2
    exit 2
  fi
done

openblas_dir=/usr/lib/x86_64-linux-gnu/openblas-pthread
if [[ -d "$openblas_dir" ]]; then
  export LD_LIBRARY_PATH="$openblas_dir${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
fi
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
# glibc returns freed blocks above its mmap threshold to the kernel, and PyTorch frees and
# allocates its activation tensors on every pass: on a virtual machine where page faults
# are dear, the peer's fit at width 64 read 24-146 ms per run of ten (median about 70)
# by default and 19-22 ms with freed memory kept (the same 2-core AMD EPYC, one thread).
# Both programs run with it kept (tactfunc reuses its buffers anyway), the peer at its
# best, as with a caching allocator; a GLIBC_TUNABLES already set is kept.
export GLIBC_TUNABLES="${GLIBC_TUNABLES:-glibc.malloc.mmap_threshold=33554432:glibc.malloc.trim_threshold=4294967296}"

python=""
for candidate in "${PYTHON:-}" python3 /usr/bin/python3; do
  [[ -n "$candidate" ]] || continue
  if "$candidate" -c 'import torch' >/dev/null 2>&1; then
    python="$candidate"
    break
  fi
done
if [[ -z "$python" ]]; then
  cat <<'EOF'
bench_peer: PyTorch is not importable (tried $PYTHON, python3, /usr/bin/python3).
  Install it to run this comparison (Debian/Ubuntu, as root):
    apt-get install -y python3-torch
  and OpenBLAS, the BLAS a PyTorch user on the CPU would pick:
    apt-get install -y libopenblas0-pthread
  (this script then sets LD_LIBRARY_PATH=/usr/lib/x86_64-linux-gnu/openblas-pthread;
  or select it system-wide: update-alternatives --config libblas.so.3-x86_64-linux-gnu).
bench_peer: skipped
EOF
  exit 0
fi

# OpenBLAS picks its kernels from the CPU's model number. A virtual machine that hides
# the model (e.g. "Intel(R) Xeon(R) Processor") makes OpenBLAS 0.3.21 fall back to its
# Prescott (SSE3) kernels, a third of the float GEMM rate its AVX-512 ones reach on the
# same core (34 against 109 GFLOP/s for 4096x256 times 256x256 on such a machine). The
# peer is compared at its best: on that fallback the core type is set from the CPU's
# flags (SkylakeX with AVX-512, Haswell with AVX2 and FMA), unless OPENBLAS_CORETYPE is
# already set.
openblas_core() {
  OPENBLAS_VERBOSE=2 "$python" -c 'import torch; torch.ones(2, 2) @ torch.ones(2, 2)' 2>&1 |
    sed -n 's/^Core: //p' | head -n 1
}
core="$(openblas_core || true)"
if [[ -d "$openblas_dir" && -z "${OPENBLAS_CORETYPE:-}" ]]; then
  if [[ "$core" == "Prescott" || "$core" == "Core2" || "$core" == "Nehalem" ]]; then
    flags="$(grep -m1 '^flags' /proc/cpuinfo 2>/dev/null || true)"
    if [[ " $flags " == *" avx512f "* ]]; then
      export OPENBLAS_CORETYPE=SkylakeX
    elif [[ " $flags " == *" avx2 "* && " $flags " == *" fma "* ]]; then
      export OPENBLAS_CORETYPE=Haswell
    fi
    if [[ -n "${OPENBLAS_CORETYPE:-}" ]]; then
      echo "bench_peer: OpenBLAS chose its $core kernels for this CPU; set OPENBLAS_CORETYPE=$OPENBLAS_CORETYPE from the CPU's flags"
      core="$(openblas_core || true)"  # what it runs with now
    fi
  fi
fi
# On a CPU with AVX-512 that OpenBLAS 0.3.21 does not know as such (an AMD Zen 4 is
# run with its Haswell AVX2 kernels) the AVX-512 kernels can be far faster: measured on
# such a 2-core AMD EPYC, one thread, 4096x256 times 256x256, Haswell 99.7 and SkylakeX
# 171.5 GFLOP/s. Both are timed here and the peer runs with the faster, also when
# OPENBLAS_CORETYPE was set before (that machine's environment set it to Haswell).
gemm_rate() {
  OPENBLAS_CORETYPE="$1" "$python" - <<'PY'
import time, torch
torch.set_num_threads(1)
a, b = torch.randn(4096, 256), torch.randn(256, 256)
best = 0.0
for _ in range(20):
    start = time.perf_counter(); a @ b; best = max(best, 2 * 4096 * 256 * 256 / (time.perf_counter() - start) / 1e9)
print(f"{best:.1f}")
PY
}
rate=""  # OpenBLAS's rate with the kernels the peer runs with, once measured
if [[ -d "$openblas_dir" && -n "$core" && "$core" != "SkylakeX" &&
      "$core" != "Cooperlake" && "$core" != "SapphireRapids" ]]; then
  flags="$(grep -m1 '^flags' /proc/cpuinfo 2>/dev/null || true)"
  if [[ " $flags " == *" avx512f "* ]]; then
    own_rate="$(gemm_rate "$core" || true)"
    avx512_rate="$(gemm_rate SkylakeX || true)"
    echo "bench_peer: OpenBLAS float GEMM 4096x256x256, one thread: $core kernels $own_rate, SkylakeX (AVX-512) kernels $avx512_rate GFLOP/s"
    rate="$own_rate"
    if awk -v a="$avx512_rate" -v b="$own_rate" 'BEGIN { exit !(a > b) }'; then
      export OPENBLAS_CORETYPE=SkylakeX
      core="$(openblas_core || true)"
      rate="$avx512_rate"
    fi
  fi
fi
echo "bench_peer: OpenBLAS kernels: $core"
# The machine's single-thread float GEMM rate by a standard BLAS, beside the reference
# product `bench trunk` times with tactfunc's own kernels (gemm_gflops in its JSON): the
# shares of the GEMM rate can be read against either.
if [[ -d "$openblas_dir" && -n "$core" ]]; then
  [[ -n "$rate" ]] || rate="$(gemm_rate "$core" || echo n/a)"
  echo "bench_peer: OpenBLAS float GEMM 4096x256x256, one thread, best of 20: $rate GFLOP/s"
fi

tactfunc="${TACTFUNC:-build/bin/tactfunc}"
if [[ ! -x "$tactfunc" ]]; then
  echo "bench_peer: $tactfunc not found; build first (scripts/build.sh)" >&2
  exit 1
fi

if [[ -z "$out" ]]; then
  out="$(mktemp -d)"
  trap 'rm -rf "$out"' EXIT
fi
mkdir -p "$out"
peer="scripts/peer/torch_trunk.py"
common=(--rows 70 --cols 88 --steps 3 --batch 32 --pixels 512)

echo "bench_peer: $rounds rounds; fits x $repeats, meta steps x $meta_repeats per run; sizes $sizes"
echo "bench_peer: products: tactfunc $products, PyTorch $peer_products"
echo "bench_peer: python $python; LD_LIBRARY_PATH=${LD_LIBRARY_PATH:-}; GLIBC_TUNABLES=$GLIBC_TUNABLES"
echo "bench_peer: load average at the start: $(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null || echo n/a)"
IFS=',' read -r -a size_list <<<"$sizes"
for size in "${size_list[@]}"; do
  IFS=':' read -r width layers latent <<<"$size"
  shape=(--width "$width" --layers "$layers" --latent "$latent" "${common[@]}")
  # The FLOPs PyTorch's profiler counts, once per size (not timed).
  "$python" "$peer" flops "${shape[@]}" >"$out/flops_$size.json"
done
for round in $(seq 1 "$rounds"); do
  for size in "${size_list[@]}"; do
    IFS=':' read -r width layers latent <<<"$size"
    shape=(--width "$width" --layers "$layers" --latent "$latent" "${common[@]}")
    echo "bench_peer: round $round/$rounds, size $size: tactfunc ..."
    "$tactfunc" bench trunk "${shape[@]}" --threads 1 --repeats "$repeats" \
      --workloads fit --products "$products" --json | tail -n 1 \
      >"$out/tactfunc_fit_${size}_$round.json"
    echo "bench_peer: round $round/$rounds, size $size: pytorch ..."
    "$python" "$peer" fit "${shape[@]}" --threads 1 --repeats "$repeats" \
      --products "$peer_products" \
      >"$out/pytorch_fit_${size}_$round.json"
    "$tactfunc" bench trunk "${shape[@]}" --threads 1 --repeats "$meta_repeats" \
      --workloads meta-step --products "$products" --json | tail -n 1 \
      >"$out/tactfunc_meta_${size}_$round.json"
    "$python" "$peer" meta-step "${shape[@]}" --threads 1 --repeats "$meta_repeats" \
      --products "$peer_products" \
      >"$out/pytorch_meta_${size}_$round.json"
  done
done

echo "bench_peer: load average at the end: $(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null || echo n/a)"
"$python" - "$out" "$rounds" "$sizes" "$products" "$peer_products" <<'EOF'
import json, statistics, sys
out, rounds, sizes = sys.argv[1], int(sys.argv[2]), sys.argv[3].split(",")
products, peer_products = sys.argv[4], sys.argv[5]
def load(name):
    with open(f"{out}/{name}.json") as f:
        return json.loads(f.read().strip().splitlines()[-1])
rows, blas, torch_version, summary, fixed = [], set(), "", [], []
print()
print("| trunk | workload | tactfunc ms (median of rounds) | PyTorch ms | PyTorch / tactfunc, median | range | GEMM GFLOP tactfunc | GEMM GFLOP PyTorch (profiled) |")
print("|---|---|---:|---:|---:|---|---:|---:|")
for size in sizes:
    w, l, d = size.split(":")
    flops = load(f"flops_{size}")
    per = {"fit core": [], "full fit": [], "meta step": []}
    times = {k: ([], []) for k in per}
    tf_flops = {}
    for r in range(1, rounds + 1):
        tf, pt = load(f"tactfunc_fit_{size}_{r}"), load(f"pytorch_fit_{size}_{r}")
        tfm, ptm = load(f"tactfunc_meta_{size}_{r}"), load(f"pytorch_meta_{size}_{r}")
        blas.update(pt["blas"]); torch_version = pt["torch"]
        pairs = {"fit core": (tf["fit"]["core_ms_median"], pt["core_ms_median"]),
                 "full fit": (tf["fit"]["full_ms_median"], pt["full_ms_median"]),
                 "meta step": (tfm["meta_step"]["ms_median"], ptm["ms_median"])}
        for k, (a, b) in pairs.items():
            per[k].append(b / a)
            times[k][0].append(a); times[k][1].append(b)
        # tactfunc's fixed costs: its whole fit over the steps as that fit runs them.
        fixed.append((size, tf["fit"]["full_ms_median"] / tf["fit"]["fit_steps_ms_median"] - 1,
                      tf["fit"]["start_pass_ms"]))
        tf_flops = {"fit core": tf["fit"]["core_gemm_gflop"], "full fit": tf["fit"]["full_gemm_gflop"],
                    "meta step": tfm["meta_step"]["gemm_gflop"]}
    pt_flops = {"fit core": flops["profiled_fit_core_gemm_gflop"],
                "full fit": flops["profiled_fit_full_gemm_gflop"],
                "meta step": flops["profiled_meta_step_gemm_gflop"]}
    for k, ratios in per.items():
        med = statistics.median(ratios)
        print(f"| width {w}, {l} layers, d {d} | {k} | {statistics.median(times[k][0]):.4g} | "
              f"{statistics.median(times[k][1]):.4g} | {med:.2f} | {min(ratios):.2f}-{max(ratios):.2f} | "
              f"{tf_flops[k]:.3g} | {pt_flops[k]:.3g} |")
        summary.append({"width": int(w), "layers": int(l), "latent": int(d), "workload": k,
                        "ratio_median": med, "ratio_min": min(ratios), "ratio_max": max(ratios),
                        "tactfunc_ms_median": statistics.median(times[k][0]),
                        "pytorch_ms_median": statistics.median(times[k][1]),
                        "tactfunc_gemm_gflop": tf_flops[k], "pytorch_gemm_gflop": pt_flops[k]})
print()
print("fit core: the K steps, each a full trunk pass in both programs; full fit: everything a fit does,")
print("tactfunc's first step from its pass at z = 0 (outputs and latent Jacobian, frame-independent,")
print("made once per frame size; not in the fit's time, like the peer's model set-up)")
for size in sizes:
    shares = [f for s2, f, _ in fixed if s2 == size]
    passes = [p for s2, _, p in fixed if s2 == size]
    print(f"tactfunc {size}: fixed costs (whole fit over its steps, minus one) "
          f"{100 * statistics.median(shares):.0f} % ({100 * min(shares):.0f}-{100 * max(shares):.0f}); "
          f"the pass at z = 0 {statistics.median(passes):.3g} ms once")
print(f"PyTorch {torch_version}; BLAS mapped by the PyTorch process: {', '.join(sorted(blas)) or 'none found'}")
print(f"rounds: {rounds}; ratio = PyTorch time / tactfunc time per round (each time a median over its run's repeats)")
print(f"products: tactfunc {products}, PyTorch {peer_products}")
print(json.dumps({"bench": "peer", "torch": torch_version, "blas": sorted(blas), "rounds": rounds,
                  "products": products, "peer_products": peer_products,
                  "results": summary}))
EOF
