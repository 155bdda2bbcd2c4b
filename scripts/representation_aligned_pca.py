#!/usr/bin/env python3
"""A study of PCA in the contact's own frame: every frame is moved and turned so that its
contact sits at the origin along its principal axis, a linear basis is learned on those
aligned frames, and each frame is stored as its pose (3 values) plus its aligned code.

Why: a linear basis spends many components on a contact that only moved or turned (a
shifted edge is not a re-weighted edge). Aligning the frames first leaves the basis the
shape of the contacts; the price is three values per frame and two bilinear resamplings,
whose own loss this script reports ("resampling only": warp and unwarp the noise-free
frame with no code at all, the best any code in that frame can score).

Pose: the centroid t and principal axis theta of the frame's difference energy over its
valid pixels (theta modulo pi from the second moments; the sign is chosen so that the
third moment along the axis is positive, which makes a one-sided contact turn the same
way every time). Aligned frame A(q) = F(t + R(theta) q) on a square grid of side
`--canvas` x the frame's diagonal, `--upsample` samples per pixel (samples outside the
frame read 0); reconstruction F(p) = A(R(-theta) (p - t)).

Every value is stored as float16 (or, with `--precision uint8`, `uint6` or `uint4`, the
code values as b-bit codes on the functaset's per-dimension grid and the pose values as
float16): the aligned components plus the 2 or 3 pose values fill the same bytes as PCA
with bytes x 8 / b components. Scored as `tactfunc eval`
scores (representation_common.psnr_per_frame) against the noise-free test frames, the
basis fitted on the noisy train split of the evaluation set (as eval's PCA).

  python3 scripts/representation_aligned_pca.py --eval /tmp/export_eval --sensor bubble \\
      --bytes 128 256 --out /tmp/aligned_pca_bubble.json

`--basis-data DIR` learns the aligned basis from the train split of another export (a
recording of more contacts, as a pretrained model sees) and also scores plain PCA learned
from those frames; `--shrink` shrinks every code by its Wiener gain before it is stored.

Input: `tactfunc export --clean` of the train and test splits (docs/CLI.md). Needs NumPy and
PyTorch (bilinear sampling). Deterministic.
"""
import argparse
import json
import math
import os
import sys

try:
    import numpy as np
    import torch
    import torch.nn.functional as F
except ImportError as e:  # pragma: no cover
    sys.exit(f"representation_aligned_pca.py: needs NumPy and PyTorch ({e})")

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from representation_common import energy_moments, psnr_per_frame, write_sheet  # noqa: E402


def load(directory, name):
    path = os.path.join(directory, name + ".npy")
    if not os.path.exists(path):
        sys.exit(f"representation_aligned_pca.py: {path} is missing (run `tactfunc export "
                 f"--clean` with the split it names)")
    return np.load(path)


def moment_poses(frames, weights):
    """(t_row, t_col, theta, spread) per frame, in pixels about the frame's centre; theta
    turned by pi where the energy is skewed the other way along the axis."""
    n, h, w, _ = frames.shape
    rr, cc = np.meshgrid(np.arange(h) - (h - 1) / 2, np.arange(w) - (w - 1) / 2, indexing="ij")
    t, theta, skew, spread = energy_moments(frames, np.stack([rr.ravel(), cc.ravel()], 1),
                                            weights)
    theta = np.where(skew < 0, theta + math.pi, theta)
    poses = np.stack([t[:, 0], t[:, 1], theta, spread], 1)
    poses[spread == 0, 3] = 1
    return poses


def sample(images, points, h, w):
    """Bilinear samples of images (n, h, w, c) at points (n, m, 2) in pixels about the
    centre, (row, col); 0 outside."""
    grid = torch.stack([points[..., 1] / ((w - 1) / 2), points[..., 0] / ((h - 1) / 2)], -1)
    out = F.grid_sample(torch.from_numpy(images).permute(0, 3, 1, 2).double(),
                        grid[:, :, None, :], mode="bilinear", padding_mode="zeros",
                        align_corners=True)[..., 0]
    return out.permute(0, 2, 1).numpy()  # (n, m, c)


class Canvas:
    def __init__(self, h, w, canvas, upsample):
        half = canvas * math.hypot(h, w) / 2
        self.side = int(math.ceil(2 * half * upsample)) | 1
        s = np.linspace(-half, half, self.side)
        rr, cc = np.meshgrid(s, s, indexing="ij")
        self.q = torch.from_numpy(np.stack([rr.ravel(), cc.ravel()], 1))
        self.half, self.h, self.w = half, h, w

    def align(self, frames, poses):
        p = torch.from_numpy(poses)
        c, s = torch.cos(p[:, 2])[:, None], torch.sin(p[:, 2])[:, None]
        q0, q1 = self.q[None, :, 0], self.q[None, :, 1]
        k = p[:, 3:4]
        pts = torch.stack([p[:, None, 0] + k * (c * q0 - s * q1),
                           p[:, None, 1] + k * (s * q0 + c * q1)], -1)
        out = sample(frames, pts, self.h, self.w)
        return out.reshape(len(frames), -1)

    def unalign(self, aligned, poses, channels):
        n = len(aligned)
        canvas = aligned.reshape(n, self.side, self.side, channels)
        rr, cc = np.meshgrid(np.arange(self.h) - (self.h - 1) / 2,
                             np.arange(self.w) - (self.w - 1) / 2, indexing="ij")
        p = torch.from_numpy(poses)
        c, s = torch.cos(p[:, 2])[:, None], torch.sin(p[:, 2])[:, None]
        d0 = torch.from_numpy(rr.ravel())[None] - p[:, None, 0]
        d1 = torch.from_numpy(cc.ravel())[None] - p[:, None, 1]
        k = p[:, 3:4]
        q = torch.stack([c * d0 + s * d1, -s * d0 + c * d1], -1) / k[..., None]  # R(-theta) (p - t) / k
        # Canvas coordinates as "pixels about the centre" of a side x side image.
        scale = (self.side - 1) / (2 * self.half)
        out = sample(canvas, q * scale, self.side, self.side)
        return out.reshape(n, self.h, self.w, channels)


def blur(frames, sigma):
    """Separable Gaussian blur of (n, h, w, c) frames, edges replicated."""
    if sigma <= 0:
        return frames
    radius = int(math.ceil(3 * sigma))
    taps = torch.exp(-0.5 * (torch.arange(-radius, radius + 1, dtype=torch.float64) / sigma) ** 2)
    taps /= taps.sum()
    x = torch.from_numpy(frames).permute(0, 3, 1, 2).reshape(-1, 1, *frames.shape[1:3])
    x = F.conv2d(F.pad(x, (radius, radius, 0, 0), mode="replicate"), taps.view(1, 1, 1, -1))
    x = F.conv2d(F.pad(x, (0, 0, radius, radius), mode="replicate"), taps.view(1, 1, -1, 1))
    return x.reshape(frames.shape[0], frames.shape[3], *frames.shape[1:3]).permute(
        0, 2, 3, 1).numpy()


def pca(x, k):
    mean = x.mean(0)
    xc = x - mean
    if len(x) > 4000:  # a large basis set: randomised SVD (Halko et al.), 6 power iterations
        torch.manual_seed(0)  # the sketch's draws: the same basis on every run
        _, _, v = torch.svd_lowrank(torch.from_numpy(xc), q=k + 32, niter=6)
        return mean, v[:, :k].numpy()
    vals, vecs = np.linalg.eigh(xc @ xc.T)
    order = np.argsort(vals)[::-1][:k]
    basis = (xc.T @ vecs[:, order]) / np.sqrt(np.maximum(vals[order], 1e-30))
    return mean, basis


def shrunk_pca(x, k, shrink):
    """pca(x, k) and each component's code gain: 1, or with `shrink` its Wiener gain
    max(0, (l_k - s2) / l_k), l_k the component's variance over x and s2 the noise floor,
    the median variance of components k..2k."""
    if not shrink:
        mean, basis = pca(x, k)
        return mean, basis, np.ones(k)
    mean, basis = pca(x, 2 * k)
    var = (((x - mean) @ basis) ** 2).mean(0)
    noise = np.median(var[k:])
    gains = np.maximum(0.0, (var[:k] - noise) / var[:k])
    print(f"shrink: noise floor {noise:.3g}, gains {gains[0]:.3f} .. {gains[-1]:.3f}, "
          f"{int((gains == 0).sum())} of {k} off", flush=True)
    return mean, basis[:, :k], gains


def unexplained(aligned, mean, basis):
    """Per frame, the energy the basis leaves out of the aligned frame."""
    centred = aligned - mean
    return (centred ** 2).sum(1) - ((centred @ basis) ** 2).sum(1)


def refine_poses(canvas, frames, poses, mean, basis):
    """Coordinate search of each frame's translation that minimises unexplained()."""
    poses = poses.copy()
    best = unexplained(canvas.align(frames, poses), mean, basis)
    for step in (1.0, 0.5, 0.25):
        for dr, dc in ((a, b) for a in (-step, 0, step) for b in (-step, 0, step)):
            if dr == 0 and dc == 0:
                continue
            trial = poses.copy()
            trial[:, 0] += dr
            trial[:, 1] += dc
            err = unexplained(canvas.align(frames, trial), mean, basis)
            better = err < best
            poses[better] = trial[better]
            best[better] = err[better]
    return poses


def mixture_codes(aligned_train, aligned_test, clusters, components, precision):
    """A mixture of aligned bases: k-means (30 rounds, seed 0) of the train frames' first
    32 aligned PCA codes into `clusters` groups, one basis of `components` per group;
    each test frame is coded by the basis that explains its (noisy) aligned frame best
    (the group's index takes one value's bytes). Returns the reconstructed aligned frames."""
    mean, basis = pca(aligned_train, 32)
    features = (aligned_train - mean) @ basis
    rng = np.random.default_rng(0)
    centres = features[rng.choice(len(features), clusters, replace=False)]
    for _ in range(30):
        label = ((features[:, None] - centres[None]) ** 2).sum(-1).argmin(1)
        for k in range(clusters):
            if (label == k).any():
                centres[k] = features[label == k].mean(0)
    models = [pca(aligned_train[label == k], min(components, int((label == k).sum()) - 1))
              for k in range(clusters)]
    pick = np.stack([unexplained(aligned_test, m, b) for m, b in models], 1).argmin(1)
    out = np.zeros_like(aligned_test)
    for k, (m, b) in enumerate(models):
        chosen = pick == k
        if chosen.any():
            out[chosen] = store((aligned_test[chosen] - m) @ b, precision) @ b.T + m
    return out


def store(codes, precision):
    """Codes as stored: float16, or b-bit codes (`uint8`, `uint6`, `uint4`) on the
    functaset's grid (per dimension, the min and max over the stored frames, 2^b - 1
    steps; docs/FUNCTASET.md, b-bit codes)."""
    if precision == "float16":
        return codes.astype(np.float16).astype(np.float64)
    levels = (1 << BITS[precision]) - 1
    lo, hi = codes.min(0), codes.max(0)
    step = np.where(hi > lo, (hi - lo) / levels, 1.0)
    return lo + np.clip(np.rint((codes - lo) / step), 0, levels) * step


BITS = {"float16": 16, "uint8": 8, "uint6": 6, "uint4": 4}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--eval", required=True,
                    help="`tactfunc export --clean` dir with the train and test splits")
    ap.add_argument("--sensor", default="bubble")
    ap.add_argument("--bytes", type=int, nargs="+", default=[128, 256])
    ap.add_argument("--canvas", type=float, default=1.0,
                    help="aligned grid's side as a multiple of the frame's diagonal")
    ap.add_argument("--upsample", type=float, default=1.0, help="aligned samples per pixel")
    ap.add_argument("--translate-only", action="store_true",
                    help="align by the centroid only (theta = 0)")
    ap.add_argument("--scale", action="store_true",
                    help="also scale each frame by the spread of its energy (one more value)")
    ap.add_argument("--residual", type=int, default=0,
                    help="spend this many of the components on a sensor-frame PCA of what "
                         "the aligned code leaves (the rim, the dome: what does not move)")
    ap.add_argument("--refine", type=int, default=0,
                    help="rounds of pose refinement: each frame's centroid is moved (3 x 3 "
                         "searches at 1, 1/2, 1/4 px) to where the aligned basis explains its "
                         "(noisy) frame best, and the train basis is refitted")
    ap.add_argument("--blur", type=float, default=0.0,
                    help="Gaussian sigma (px) of a blur of the TRAIN frames before the basis is "
                         "learned (a smoothness prior against their noise; test frames are "
                         "coded as they are)")
    ap.add_argument("--clusters", type=int, default=1,
                    help="a mixture of this many aligned bases (k-means groups of the train "
                         "frames), each test frame coded by its best one")
    ap.add_argument("--basis-from-clean", action="store_true",
                    help="learn both bases from the NOISE-FREE train frames (a bound: what a "
                         "basis free of the sensor noise would give; needs their export); "
                         "with --basis-data, from that export's noise-free frames, eval's "
                         "PCA staying on --eval's noisy ones")
    ap.add_argument("--basis-data",
                    help="learn the aligned basis from the train split of this `tactfunc "
                         "export` dir instead (more contacts than the evaluation set's train "
                         "split, as a pretrained model sees); eval's PCA stays on --eval's")
    ap.add_argument("--shrink", action="store_true",
                    help="shrink each aligned code by its Wiener gain max(0, (l_k - s2) / l_k) "
                         "before it is stored (l_k: the variance of component k over the basis "
                         "frames; s2, the noise floor: the median variance of components k..2k "
                         "of the same basis): the MMSE linear code, same bytes")
    ap.add_argument("--precision", choices=list(BITS), default="float16",
                    help="how every code value is stored (PCA and aligned alike; the pose "
                         "values stay float16): bytes x 8 / bits components")
    ap.add_argument("--out", help="write the figures as JSON here")
    args = ap.parse_args()

    if args.basis_data and (args.scale or args.refine or args.residual or args.clusters > 1):
        sys.exit("representation_aligned_pca.py: --basis-data goes with the translation or "
                 "moment-angle alignment alone (not --scale, --refine, --residual or "
                 "--clusters)")
    if args.clusters > 1 and args.shrink:
        sys.exit("representation_aligned_pca.py: --shrink does not go with --clusters")
    train = load(args.eval, f"{args.sensor}_train").astype(np.float64)
    test = load(args.eval, f"{args.sensor}_test").astype(np.float64)
    clean = load(args.eval, f"{args.sensor}_test_clean").astype(np.float64)
    wpath = os.path.join(args.eval, f"{args.sensor}_test_weights.npy")
    test_w = np.load(wpath) if os.path.exists(wpath) else np.ones(test.shape[:3], np.float32)
    trpath = os.path.join(args.eval, f"{args.sensor}_train_weights.npy")
    train_w = np.load(trpath) if os.path.exists(trpath) else np.ones(train.shape[:3], np.float32)
    n, h, w, c = train.shape
    canvas = Canvas(h, w, args.canvas, args.upsample)
    print(f"{args.sensor}: {n} train / {len(test)} test frames of {h}x{w}x{c}; aligned canvas "
          f"{canvas.side}x{canvas.side}", flush=True)

    train_pose = moment_poses(train, train_w)
    test_pose = moment_poses(test, test_w)
    if args.translate_only:
        train_pose[:, 2] = 0
        test_pose[:, 2] = 0
    if args.scale:  # relative to the median spread of the train contacts
        typical = np.median(train_pose[:, 3])
        train_pose[:, 3] /= typical
        test_pose[:, 3] /= typical
    else:
        train_pose[:, 3] = 1
        test_pose[:, 3] = 1
    test_pose16 = test_pose.astype(np.float16).astype(np.float64)
    if args.basis_from_clean and not args.basis_data:
        train = load(args.eval, f"{args.sensor}_train_clean").astype(np.float64)
    basis_train, basis_pose = blur(train, args.blur), train_pose
    if args.basis_data:
        more = load(args.basis_data, f"{args.sensor}_train"
                    + ("_clean" if args.basis_from_clean else "")).astype(np.float64)
        mpath = os.path.join(args.basis_data, f"{args.sensor}_train_weights.npy")
        more_w = np.load(mpath) if os.path.exists(mpath) else np.ones(more.shape[:3], np.float32)
        basis_pose = moment_poses(more, more_w)
        if args.translate_only:
            basis_pose[:, 2] = 0
        basis_pose[:, 3] = 1
        basis_train = blur(more, args.blur)
        print(f"aligned basis learned from {len(more)} frames of {args.basis_data}", flush=True)
    aligned_train = canvas.align(basis_train, basis_pose)
    resampled = canvas.unalign(canvas.align(clean, test_pose16), test_pose16, c)
    result = {"sensor": args.sensor, "canvas": args.canvas, "upsample": args.upsample,
              "basis_from_clean": args.basis_from_clean,
              "translate_only": args.translate_only, "clusters": args.clusters, "scale": args.scale, "blur": args.blur,
              "refine": args.refine, "shrink": args.shrink,
              "basis_data": args.basis_data,
              "canvas_side": canvas.side,
              "resampling_only_psnr_clean": float(psnr_per_frame(resampled, clean, test_w).mean()),
              "rows": []}
    print(f"resampling only (noise-free frame warped and unwarped): "
          f"{result['resampling_only_psnr_clean']:.2f} dB", flush=True)
    flat_train = train.reshape(n, -1)  # eval's PCA: the noisy train frames as they are
    for bytes_per_frame in args.bytes:
        k_plain = bytes_per_frame * 8 // BITS[args.precision]
        pose_values = (2 if args.translate_only else 3) + (1 if args.scale else 0)
        # The pose values take 2 bytes each: the code values they displace, rounded up.
        k_aligned = k_plain - -(-pose_values * 16 // BITS[args.precision]) \
            - args.residual
        mean, basis = pca(flat_train, k_plain)
        codes = store((test.reshape(len(test), -1) - mean) @ basis, args.precision)
        plain = (codes @ basis.T + mean).reshape(test.shape)
        amean, abasis, gains = shrunk_pca(aligned_train, k_aligned, args.shrink)
        train_pose_k, test_pose_k = train_pose, test_pose16
        for _ in range(args.refine):
            train_pose_k = refine_poses(canvas, train, train_pose_k, amean, abasis)
            amean, abasis = pca(canvas.align(train, train_pose_k), k_aligned)
        aligned_test = canvas.align(test, test_pose16)
        if args.refine:
            test_pose_k = refine_poses(canvas, test, test_pose16, amean, abasis).astype(
                np.float16).astype(np.float64)
            aligned_test = canvas.align(test, test_pose_k)
        acodes = store(((aligned_test - amean) @ abasis) * gains, args.precision)
        aligned = canvas.unalign(acodes @ abasis.T + amean, test_pose_k, c)
        if args.clusters > 1:
            aligned = canvas.unalign(mixture_codes(aligned_train, aligned_test, args.clusters,
                                                   k_aligned - 1, args.precision),
                                     test_pose_k, c)
        if args.residual > 0:
            train_codes = (canvas.align(train, train_pose_k) - amean) @ abasis
            left = train - canvas.unalign(train_codes @ abasis.T + amean, train_pose_k, c)
            rmean, rbasis = pca(left.reshape(n, -1), args.residual)
            rcodes = ((test - aligned).reshape(len(test), -1) - rmean) @ rbasis
            aligned = aligned + (store(rcodes, args.precision) @ rbasis.T
                                 + rmean).reshape(test.shape)
        row = {"bytes_per_frame": bytes_per_frame, "precision": args.precision,
               "pca_components": k_plain,
               "pca_psnr_clean": float(psnr_per_frame(plain, clean, test_w).mean()),
               "aligned_components": k_aligned, "residual_components": args.residual,
               "aligned_psnr_clean": float(psnr_per_frame(aligned, clean, test_w).mean())}
        row["margin"] = row["aligned_psnr_clean"] - row["pca_psnr_clean"]
        if args.basis_data:
            # Plain PCA given the same contacts as the aligned basis (and the same shrinkage):
            # how much of the margin is the data, how much the alignment.
            pmean, pbasis, pgains = shrunk_pca(more.reshape(len(more), -1), k_plain, args.shrink)
            pcodes = store(((test.reshape(len(test), -1) - pmean) @ pbasis) * pgains,
                           args.precision)
            row["pca_basis_data_psnr_clean"] = float(psnr_per_frame(
                (pcodes @ pbasis.T + pmean).reshape(test.shape), clean, test_w).mean())
        result["rows"].append(row)
        if args.out and bytes_per_frame == args.bytes[0]:
            picture = os.path.splitext(args.out)[0] + ".png"
            write_sheet(picture, [clean, plain, aligned], count=6)
            print(f"wrote {picture} (rows: noise-free frame, PCA with the same bits, PCA in "
                  f"the contact's frame; {bytes_per_frame} B per frame)", flush=True)
        print(json.dumps(row), flush=True)
    if args.out:
        with open(args.out + ".tmp", "w") as f:
            json.dump(result, f, indent=1)
        os.replace(args.out + ".tmp", args.out)


if __name__ == "__main__":
    main()
