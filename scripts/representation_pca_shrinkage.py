#!/usr/bin/env python3
"""PCA codes shrunk towards the prior: how much of the sensor noise a linear code can
leave out by itself.

A frame's PCA code c_k = b_k . (y - mean) carries the frame's noise along every basis
vector. Shrinking each code towards 0 by the Wiener gain g_k = max(0, (l_k - s2) / l_k),
with l_k the k-th eigenvalue of the train frames' covariance and s2 the noise floor (the
median eigenvalue far in the tail, components `--floor-from` to 2 x that), is the MMSE
linear estimate under a Gaussian prior. The gains are part of the basis (stored once), so
the bytes per frame do not change. Scored as `tactfunc eval` scores (PSNR with the
target's range as the peak, against the noise-free frames; codes stored as float16).

Input: a `tactfunc export --clean --split all` directory (docs/CLI.md), e.g.

  tactfunc synth --out /tmp/bb --frames-per-tool 150 --sensors bubble --seed 4242 --clean
  tactfunc export --data /tmp/bb --model models/pretrained/default.tfm --out /tmp/ex_bb \\
      --sensors bubble --split all --clean
  python3 scripts/representation_pca_shrinkage.py --eval /tmp/ex_bb --sensor bubble

Needs NumPy.
"""
import argparse
import json
import os
import sys

try:
    import numpy as np
except ImportError as e:  # pragma: no cover
    sys.exit(f"representation_pca_shrinkage.py: needs NumPy ({e})")

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from representation_common import psnr_per_frame  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--eval", required=True, help="`tactfunc export --clean --split all` dir")
    ap.add_argument("--sensor", default="bubble")
    ap.add_argument("--components", default="32,64,128")
    ap.add_argument("--floor-from", type=int, default=300)
    args = ap.parse_args()
    base = os.path.join(args.eval, args.sensor + "_all")
    for suffix in ("", "_clean", "_weights"):
        if not os.path.exists(base + suffix + ".npy"):
            sys.exit(f"representation_pca_shrinkage.py: {base + suffix}.npy is missing (run "
                     "`tactfunc export --clean --split all`)")
    frames = np.load(base + ".npy")
    clean = np.load(base + "_clean.npy")
    weights = np.load(base + "_weights.npy")
    meta = json.load(open(os.path.join(args.eval, "export.json")))
    split = np.array([f["split"] for f in meta["sensors"][args.sensor]["frames"]])
    train, test = split == "train", split == "test"
    x = frames[train].reshape(train.sum(), -1).astype(np.float64)
    mean = x.mean(0)
    _, s, vt = np.linalg.svd(x - mean, full_matrices=False)
    eig = s ** 2 / len(x)
    floor = float(np.median(eig[args.floor_from:2 * args.floor_from]))
    y = frames[test].reshape(test.sum(), -1).astype(np.float64) - mean
    rows = []
    for k in (int(v) for v in args.components.split(",")):
        basis = vt[:k].T
        codes = y @ basis
        gain = np.clip((eig[:k] - floor) / eig[:k], 0, 1)
        row = {"components": k, "bytes_per_frame_float16": 2 * k}
        for name, c in (("plain", codes), ("shrunk", codes * gain)):
            rec = (c.astype(np.float16).astype(np.float64) @ basis.T + mean).reshape(clean[test].shape)
            row[name + "_clean"] = float(psnr_per_frame(rec, clean[test], weights[test]).mean())
        rows.append(row)
        print(f"{args.sensor}: {k} float16 components ({2 * k} B): plain {row['plain_clean']:.2f} dB, "
              f"shrunk {row['shrunk_clean']:.2f} dB against the noise-free test frames")
    print(json.dumps({"sensor": args.sensor, "noise_floor_eigenvalue": floor,
                      "train": int(train.sum()), "test": int(test.sum()), "rows": rows}))


if __name__ == "__main__":
    main()
