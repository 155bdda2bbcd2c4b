#!/usr/bin/env python3
"""What a linear basis of the trunk's residual would add to a functaset: each frame stored
as its latent plus k coefficients of a PCA basis of what the trunk leaves out
(frame - reconstruction), the basis learned on the train split's residuals, every test
frame's coefficients its residual's projection (unquantised: an upper bound on what k
stored coefficients can add).

Why: at 256 B per frame a d = 64 latent already holds 16 bits per value, while PCA keeps
gaining from more bytes; a residual code is the simplest way to spend more bytes on a
trunk. The script prints, per k, the test split's mean PSNR against the noise-free frames
(and the noisy ones), the residual's RMS against the sensor noise's, and the residual
spectrum's first singular values (flat = each coefficient buys little). The row "mean"
adds the train residuals' mean alone: a fixed per-pixel background stored once, no bytes
per frame (what a trunk that draws in the contact's frame cannot draw when the sensor's
background differs from its reference, as on real sensors). The row "plane" adds instead
each test frame's own least-squares plane of its residual over the sensor's pixels,
a + b col + c row per channel (3 values per channel and frame, unquantised): a bound on
what a per-frame lighting term in the sensor's coordinates would add.

  tactfunc export --data D --model M --functaset F --split all --clean --out X
  python3 scripts/representation_residual_pca.py --export X --sensor gelslim

Input: `tactfunc export --split all --functaset F` (docs/CLI.md, "export"): the frames,
their reconstructions from F and, with --clean, their noise-free copies (without them,
for real frames, the PSNR is against the frames alone). NumPy only. Deterministic.
"""
import argparse
import json
import os
import sys

try:
    import numpy as np
except ImportError as e:  # pragma: no cover
    sys.exit(f"representation_residual_pca.py: needs NumPy ({e})")

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from representation_common import psnr_per_frame  # noqa: E402


def load(directory, name, optional=False):
    path = os.path.join(directory, name)
    if optional and not os.path.exists(path):
        return None
    if not os.path.exists(path):
        sys.exit(f"representation_residual_pca.py: {path} is missing (run `tactfunc export "
                 f"--split all --clean --functaset F`)")
    return np.load(path).astype(np.float64)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--export", required=True, help="folder of `tactfunc export`")
    parser.add_argument("--sensor", default="gelslim", choices=["bubble", "gelslim"])
    parser.add_argument("--components", type=int, nargs="+",
                        default=[0, 8, 16, 32, 64, 128, 256, 512])
    args = parser.parse_args()
    s = args.sensor
    x = load(args.export, f"{s}_all.npy")
    clean = load(args.export, f"{s}_all_clean.npy", optional=True)
    recon = load(args.export, f"{s}_all_recon.npy")
    weights = load(args.export, f"{s}_all_weights.npy")
    with open(os.path.join(args.export, "export.json")) as f:
        frames = json.load(f)["sensors"][s]["frames"]
    split = np.array([frame["split"] for frame in frames])
    train, test = split == "train", split == "test"
    if not train.any() or not test.any():
        sys.exit("representation_residual_pca.py: the export needs train and test frames "
                 "(--split all)")
    n, size = len(x), x[0].size
    # Invalid pixels hold 0 in every array, so their residual is 0 and adds nothing.
    residual = (x - recon).reshape(n, size)
    mean = residual[train].mean(0)
    _, singular, basis = np.linalg.svd(residual[train] - mean, full_matrices=False)
    spread = singular / np.sqrt(train.sum())
    noise = (f"against the noise's {np.sqrt(np.mean((x[test] - clean[test]) ** 2)):.4g}"
             if clean is not None else "(no noise-free copies)")
    print(f"{s}: {train.sum()} train / {test.sum()} test frames; test residual RMS "
          f"{np.sqrt(np.mean(residual[test] ** 2)):.4g} {noise}; "
          f"residual spectrum (RMS per component) {', '.join(f'{v:.3f}' for v in spread[:8])}")
    # The reference the gains are read against: the noise-free frames where there are.
    truth = clean if clean is not None else x
    print(f"| residual components | test PSNR {'noise-free' if clean is not None else 'noisy'} "
          f"| gain | test PSNR noisy |")
    print("|---:|---:|---:|---:|")
    base = None
    rows = [(k, False) for k in args.components]
    rows.insert(1 if rows and rows[0][0] == 0 else 0, (0, True))
    for k, mean_only in rows:
        k = min(k, len(basis))
        code = (residual[test] - mean) @ basis[:k].T
        pred = recon[test] + (mean + code @ basis[:k]).reshape(recon[test].shape) \
            if k or mean_only else recon[test]
        truth_db = psnr_per_frame(pred, truth[test], weights[test]).mean()
        noisy_db = psnr_per_frame(pred, x[test], weights[test]).mean()
        base = truth_db if base is None else base
        print(f"| {'mean' if mean_only else k} | {truth_db:.2f} | {truth_db - base:+.2f} | "
              f"{noisy_db:.2f} |")
        if mean_only:
            pred = recon[test] + plane_fit(residual[test], weights[test], recon[test].shape)
            truth_db = psnr_per_frame(pred, truth[test], weights[test]).mean()
            noisy_db = psnr_per_frame(pred, x[test], weights[test]).mean()
            print(f"| plane | {truth_db:.2f} | {truth_db - base:+.2f} | {noisy_db:.2f} |")


def plane_fit(residual, weights, shape):
    """Each frame's weighted least-squares plane a + b col + c row of its residual, per
    channel, drawn over the frame (shape: frames x rows x cols [x channels])."""
    rows, cols = shape[1], shape[2]
    r, c = np.meshgrid(np.arange(rows) / rows, np.arange(cols) / cols, indexing="ij")
    design = np.stack([np.ones(rows * cols), c.ravel(), r.ravel()], axis=1)
    out = np.zeros((shape[0], rows * cols, int(np.prod(shape[3:]))))
    res = residual.reshape(shape[0], rows * cols, -1)
    w = np.asarray(weights, dtype=np.float64).reshape(shape[0], rows * cols, -1)[:, :, 0]
    for i in range(shape[0]):
        a = design * np.sqrt(w[i])[:, None]
        coef, *_ = np.linalg.lstsq(a, res[i] * np.sqrt(w[i])[:, None], rcond=None)
        out[i] = design @ coef
    return out.reshape(shape)


if __name__ == "__main__":
    main()
