#!/usr/bin/env python3
"""A study of optical-sensor representations: a SIREN that draws the gel's indentation
w(p), a learned photometric head that turns its slope into the image difference, and the
printed markers moved with the skin -- against a SIREN that draws the difference itself,
and against PCA at the same bytes per frame.

Why: on an optical sensor (GelSlim, GelSight, DIGIT) the difference image is a function
of the surface's slope (photometric stereo: each light's brightness follows n . l), plus
the markers displaced by the skin's stretch. Thin shading ridges and marker dipoles are
derivatives of a smooth field; a coordinate network's spectral bias favours the smooth
field, so drawing w and differentiating it should keep the ridges a direct SIREN blurs.

The two trunks are trained the same way (trunk and per-frame latents optimised jointly on
the noisy train frames of one dataset), then every test frame's latent is fitted to
convergence with the trunk frozen, stored as float16 (d values, 2 d bytes per frame), and
scored against the noise-free test frames with tactfunc's PSNR (per frame, the target's
range over its valid pixels as the peak; mean over frames). PCA is fitted on the noisy
train split of the evaluation dataset (as `tactfunc eval` does), its codes stored as
float32 (bytes / 4 components) and as float16 (bytes / 2 components, the same bits as the
latents).

Inputs: the `tactfunc export` directories of a training dataset and an evaluation
dataset (docs/CLI.md), e.g. (see docs/REPRESENTATION.md for the full commands):

  python3 scripts/representation_photometric.py --train /tmp/export_train \\
      --eval /tmp/export_eval --sensor gelslim --head photometric --out /tmp/photometric.json

Deterministic for a seed on a given machine and PyTorch build; needs NumPy and PyTorch.
"""
import argparse
import json
import math
import os
import sys
import time

try:
    import numpy as np
    import torch
    import torch.nn as nn
    import torch.nn.functional as F
except ImportError as e:  # pragma: no cover
    sys.exit(f"representation_photometric.py: needs NumPy and PyTorch ({e})")

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from representation_common import energy_moments, psnr_per_frame, read_png, write_sheet  # noqa: E402


def load(directory, sensor, split, clean=False):
    suffix = "_clean" if clean else ""
    path = os.path.join(directory, f"{sensor}_{split}{suffix}.npy")
    if not os.path.exists(path):
        sys.exit(f"representation_photometric.py: {path} is missing (run `tactfunc export`"
                 f"{' --clean' if clean else ''} with --split {split})")
    return np.load(path)


def pca_rows(train, test_noisy, test_clean, weights, bytes_per_frame):
    n, h, w, c = train.shape
    x = train.reshape(n, -1).astype(np.float64)
    mean = x.mean(0)
    xc = x - mean
    # Eigen-decomposition of the Gram matrix (n <= pixels here).
    gram = xc @ xc.T
    vals, vecs = np.linalg.eigh(gram)
    order = np.argsort(vals)[::-1]
    vals, vecs = vals[order], vecs[:, order]
    rows = {}
    for name, comps, dtype in (("pca_float32", bytes_per_frame // 4, np.float32),
                               ("pca_float16", bytes_per_frame // 2, np.float16)):
        k = min(comps, n - 1)
        basis = (xc.T @ vecs[:, :k]) / np.sqrt(np.maximum(vals[:k], 1e-30))
        y = test_noisy.reshape(len(test_noisy), -1).astype(np.float64) - mean
        codes = (y @ basis).astype(dtype).astype(np.float64)
        rec = (codes @ basis.T + mean).reshape(test_noisy.shape)
        rows[name] = {"components": k,
                      "psnr_clean": float(psnr_per_frame(rec, test_clean, weights).mean()),
                      "psnr_noisy": float(psnr_per_frame(rec, test_noisy, weights).mean())}
        last = rec
    return rows, last


class Trunk(nn.Module):
    """A latent-modulated SIREN (shifts = A z + c per layer, as tactfunc's trunk) with a
    choice of head:
      direct       y(p) = SIREN(p; z)                    (tactfunc's trunk)
      photometric  w(p) = SIREN(p; z)_0,
                   y(p) = S(grad w, w, p) - S(0, 0, p)   (learned photometric head)
                        + R(p - M grad w) - R(p)         (markers moved with the skin)
                        + SIREN(p; z)_1                  (a direct channel for the rest)
    where R is the sensor's reference frame (bilinearly sampled at the working resolution,
    or with markers "native" sampled at the sensor's resolution K x K times per pixel
    and averaged, as the sensor forms the frame) and M a learned 2 x 2;
      photometric_gain  the same parts multiplied as an optical sensor forms its image
                   (the skin's printed pattern, moved, times the shading of its slope):
                   y(p) = R(p - M grad w) (1 + S(grad w, w, p) - S(0, 0, p)) - R(p)
                        + SIREN(p; z)_1.
    With `transform` the first three latent values are a rigid motion of the frame's
    contact, (t_row, t_col, theta), and the SIREN draws the contact in its own frame,
    SIREN(R(-theta) (p - t); z[3:]): a contact moved or turned is three numbers, not a
    re-weighting of the whole code; with transform "translation" only t (two values),
    SIREN(p - t; z[2:]). Coordinates are then isotropic (one unit per (h - 1) / 2
    pixels along both axes), so that a rotation keeps shapes."""

    def __init__(self, head, width, layers, d, channels, reference, omega=30.0,
                 transform=False, aspect=1.0, finite_differences=False, markers="bilinear",
                 native_reference=None, supersample=4, marker_model="full"):
        super().__init__()
        self.markers, self.supersample = markers, supersample
        self.finite_differences = finite_differences
        self.head, self.omega, self.width, self.layers = head, omega, width, layers
        self.channels, self.transform, self.aspect = channels, transform, aspect
        # transform: False, "rigid" (t, theta) or "translation" (t only).
        self.pose_values = {False: 0, "rigid": 3, "translation": 2}[transform]
        code = d - self.pose_values
        self.hidden = nn.ModuleList([nn.Linear(2, width)] +
                                    [nn.Linear(width, width) for _ in range(layers - 1)])
        outputs = channels if head == "direct" else 1 + channels
        self.out = nn.Linear(width, outputs)
        self.shift = nn.Linear(code, width * layers)
        with torch.no_grad():
            self.hidden[0].weight.uniform_(-1 / 2, 1 / 2)
            for lin in list(self.hidden[1:]) + [self.out]:
                bound = math.sqrt(6 / lin.in_features) / omega
                lin.weight.uniform_(-bound, bound)
            self.shift.weight.mul_(0.1)
            self.shift.bias.zero_()
        if head != "direct":
            self.shade = nn.Sequential(nn.Linear(5, 64), nn.SiLU(), nn.Linear(64, 64), nn.SiLU(),
                                       nn.Linear(64, channels))
            # How far a unit slope moves the skin (working pixels): a full 2 x 2 matrix,
            # or one scalar times the identity (an isotropic skin moves along the slope;
            # the full matrix can settle on a sheared, one-sided solution instead).
            self.marker_model = marker_model
            if marker_model == "isotropic":
                self.marker_scale = nn.Parameter(torch.zeros(1))
            else:
                self.marker = nn.Parameter(torch.zeros(2, 2))
            # (1, C, H, W) for grid_sample.
            self.register_buffer("reference", torch.from_numpy(reference).permute(2, 0, 1)[None])
            h, w = reference.shape[:2]
            # Coordinate units per pixel along (row, col): slopes in w per pixel.
            col_unit = 2 * aspect / max(w - 1, 1)
            self.register_buffer("pixel", torch.tensor([2 / max(h - 1, 1), col_unit]))
            # From coordinates to grid_sample's [-1, 1] along (row, col).
            self.register_buffer("to_unit", torch.tensor([1.0, 1.0 / aspect]))
            if markers == "native":
                # (1, C, H, W): the reference at the sensor's own resolution, in the
                # targets' units, for markers moved before the area resize.
                self.register_buffer("native", torch.from_numpy(
                    native_reference.astype(np.float32)).permute(2, 0, 1)[None])

    def marker_matrix(self):
        if self.marker_model == "isotropic":
            return self.marker_scale * torch.eye(2)
        return self.marker

    def siren(self, x, z):
        b, p, _ = x.shape
        g = self.shift(z).view(b, 1, self.layers, self.width)
        h = x
        for l, lin in enumerate(self.hidden):
            h = torch.sin(self.omega * (lin(h) + g[:, :, l]))
        return self.out(h)

    def contact_frame(self, x, z):
        """(coordinates the SIREN sees, its latent code)."""
        if not self.transform:
            return x, z
        if self.transform == "translation":
            return x - z[:, None, :2], z[:, 2:]
        t, theta = z[:, None, :2], z[:, None, 2]
        c, s = torch.cos(theta), torch.sin(theta)
        d = x - t
        q = torch.stack([c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1]], -1)
        return q, z[:, 3:]

    def forward(self, x, z, create_graph):
        if self.head == "direct":
            return self.siren(*self.contact_frame(x, z))
        if self.finite_differences:
            # Central differences one pixel apart along rows and columns: the slope per
            # pixel from five SIREN evaluations, no second-order pass.
            p = x.shape[1]
            step_r = torch.zeros(2, dtype=x.dtype)
            step_r[0] = self.pixel[0]
            step_c = torch.zeros(2, dtype=x.dtype)
            step_c[1] = self.pixel[1]
            xs = torch.cat([x, x + step_r, x - step_r, x + step_c, x - step_c], 1)
            all_s = self.siren(*self.contact_frame(xs, z))
            s = all_s[:, :p]
            w = s[..., :1]
            wr = (all_s[:, p:2 * p, :1] - all_s[:, 2 * p:3 * p, :1]) / 2
            wc = (all_s[:, 3 * p:4 * p, :1] - all_s[:, 4 * p:, :1]) / 2
            grad = torch.cat([wr, wc], -1)
        else:
            if not x.requires_grad:
                x = x.clone().requires_grad_(True)
            s = self.siren(*self.contact_frame(x, z))
            w = s[..., :1]
            grad = torch.autograd.grad(w.sum(), x, create_graph=create_graph)[0] * self.pixel
        shade_in = torch.cat([grad, w, x], -1)
        flat_in = torch.cat([torch.zeros_like(grad), torch.zeros_like(w), x], -1)
        shading = self.shade(shade_in) - self.shade(flat_in)
        if self.markers == "native":
            sampled = self.native_markers(x, grad @ self.marker_matrix())
            at_rest = self.native_markers(x, torch.zeros_like(grad))
        else:
            moved = x - (grad @ self.marker_matrix()) * self.pixel
            ref = self.reference.expand(x.shape[0], -1, -1, -1)
            # grid_sample takes (x = column, y = row) in [-1, 1]; our coords are (row, col).
            sampled = F.grid_sample(ref, (moved * self.to_unit).flip(-1)[:, :, None, :],
                                    mode=self.markers, padding_mode="border",
                                    align_corners=True)[..., 0]
            at_rest = F.grid_sample(ref, (x * self.to_unit).flip(-1)[:, :, None, :],
                                    mode=self.markers, padding_mode="border",
                                    align_corners=True)[..., 0]
            sampled, at_rest = sampled.transpose(1, 2), at_rest.transpose(1, 2)
        if self.head == "photometric_gain":
            return sampled * (1 + shading) - at_rest + s[..., 1:]
        return shading + (sampled - at_rest) + s[..., 1:]


    def native_markers(self, x, shift):
        """The reference moved by `shift` (B, P, 2; working pixels along row, col) as the
        sensor images it: sampled bilinearly at the sensor's own resolution on a K x K grid
        inside each working pixel and averaged (the area resize of the targets), so a
        marker a pixel wide moves by a fraction of a working pixel without the blur and
        ringing of resampling the already-resized reference."""
        h, w = self.reference.shape[2:]
        H, W = self.native.shape[2:]
        k = self.supersample
        row = (x[..., 0] + 1) / 2 * (h - 1) - shift[..., 0]        # working pixel index
        col = (x[..., 1] * self.to_unit[1] + 1) / 2 * (w - 1) - shift[..., 1]
        sub = (torch.arange(k, dtype=x.dtype) + 0.5) / k             # inside the pixel
        sr, sc = H / h, W / w
        rows = (row[..., None, None] + sub[:, None]) * sr - 0.5      # native index space
        cols = (col[..., None, None] + sub[None, :]) * sc - 0.5
        rows, cols = torch.broadcast_tensors(rows, cols)
        b, p = x.shape[:2]
        grid = torch.stack([2 * cols / (W - 1) - 1, 2 * rows / (H - 1) - 1], -1)
        out = F.grid_sample(self.native.expand(b, -1, -1, -1), grid.reshape(b, p * k * k, 1, 2),
                            mode="bilinear", padding_mode="border", align_corners=True)
        return out[..., 0].reshape(b, -1, p, k * k).mean(-1).transpose(1, 2)


def render(trunk, coords, z, shape):
    """Every frame of latents z (m x d) on the full grid, as a (m, h, w, c) array."""
    out = np.zeros(shape, np.float32)
    for first in range(0, len(z), 20):
        idx = torch.arange(first, min(len(z), first + 20))
        x = coords[None].expand(len(idx), -1, -1)
        with torch.enable_grad():
            out[first:first + len(idx)] = trunk(x, z[idx], create_graph=False).detach() \
                .numpy().reshape((len(idx),) + tuple(shape[1:]))
    return out


def test_tools(directory, sensor, count):
    """The tool of every test frame from `tactfunc export`'s export.json (None without
    labels)."""
    path = os.path.join(directory, "export.json")
    if not os.path.exists(path):
        return None
    with open(path) as f:
        frames = json.load(f)["sensors"][sensor]["frames"]
    tools = [fr.get("label", {}).get("tool") for fr in frames if fr.get("split") == "test"]
    if len(tools) != count or any(t is None for t in tools):
        return None
    return np.array(tools)


def masked_mse(pred, target, valid):
    """Mean squared error over the valid pixels (valid: (..., 1) of 0 / 1)."""
    return ((pred - target) ** 2 * valid).sum() / (valid.sum() * pred.shape[-1]).clamp(min=1)


def grid(h, w, aspect=1.0):
    r = torch.linspace(-1, 1, h)
    c = torch.linspace(-aspect, aspect, w)
    rr, cc = torch.meshgrid(r, c, indexing="ij")
    return torch.stack([rr, cc], -1).reshape(-1, 2)


def moment_poses(frames, coords):
    """Per frame (t_row, t_col, theta) from the second moments of the difference's energy:
    the start of the rigid motion (theta modulo pi)."""
    t, theta, _, _ = energy_moments(frames, coords.numpy().astype(np.float64))
    return np.concatenate([t, theta[:, None]], 1).astype(np.float32)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--train", required=True, help="`tactfunc export` dir of the training set")
    ap.add_argument("--eval", required=True,
                    help="`tactfunc export --clean --split all` dir of the evaluation set")
    ap.add_argument("--sensor", default="gelslim")
    ap.add_argument("--head", choices=["direct", "photometric", "photometric_gain"],
                    default="photometric",
                    help="photometric: shading added to the moved reference; "
                         "photometric_gain: the moved reference times a shading gain")
    ap.add_argument("--transform", nargs="?", const="rigid", default=False,
                    choices=["rigid", "translation"],
                    help="the first three latent values move and turn the contact (rigid, "
                         "the default), or the first two only move it (translation)")
    ap.add_argument("--gradient", choices=["exact", "differences"], default="exact",
                    help="the photometric heads' slope: the SIREN's exact derivative, or "
                         "central differences one pixel apart (no second-order pass)")
    ap.add_argument("--markers", choices=["bilinear", "bicubic", "native"], default="bilinear",
                    help="how the photometric heads move the reference's markers: resample "
                         "the working-resolution reference (bilinear, bicubic), or sample the "
                         "sensor-resolution reference on a K x K grid per working pixel and "
                         "average (native; needs --native-reference)")
    ap.add_argument("--native-reference",
                    help="the dataset's reference image (e.g. DATA/gelslim/reference.png) for "
                         "--markers native; converted to the targets' units as tactfunc does "
                         "(grey = 0.299 R + 0.587 G + 0.114 B, divided by the export's scale)")
    ap.add_argument("--marker-warmup", type=int, default=0,
                    help="with --markers native, train the first N steps with bilinear "
                         "markers on the resized reference (smooth gradients while the head "
                         "learns how far a slope moves the skin), then switch")
    ap.add_argument("--marker-model", choices=["full", "isotropic"], default="full",
                    help="how a slope moves the markers: a learned 2 x 2 matrix (full), or "
                         "one learned scalar along the slope (isotropic)")
    ap.add_argument("--supersample", type=int, default=4,
                    help="K of --markers native (K x K samples per working pixel)")
    ap.add_argument("--width", type=int, default=64)
    ap.add_argument("--layers", type=int, default=3)
    ap.add_argument("--latent-dim", type=int, default=64)
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--pixels", type=int, default=512)
    ap.add_argument("--latent-rate", type=float, default=1e-2)
    ap.add_argument("--trunk-rate", type=float, default=1e-4)
    ap.add_argument("--fit-steps", type=int, default=400)
    ap.add_argument("--schedule", choices=["constant", "cosine"], default="constant",
                    help="training rates: constant, or a cosine decay to 1/10 over the steps")
    ap.add_argument("--fit-starts", type=int, choices=[1, 2], default=1,
                    help="with --transform, 2 fits each test frame from the moment angle and "
                         "from it + pi and keeps the lower loss on the frame's own pixels")
    ap.add_argument("--refine-steps", type=int, default=0,
                    help="after the Adam fits, refine every test latent by this many L-BFGS "
                         "iterations on all of its frame's pixels (a converged fit, as a "
                         "Levenberg-Marquardt fit would reach)")
    ap.add_argument("--save-trunk", help="save the trained trunk here (torch.save)")
    ap.add_argument("--load-trunk", help="skip training: load a trunk saved by --save-trunk "
                                         "with the same options")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", help="write the figures as JSON here")
    args = ap.parse_args()
    torch.manual_seed(args.seed)
    np.random.seed(args.seed)
    torch.set_num_threads(args.threads)

    train = load(args.train, args.sensor, "train")
    eval_train = load(args.eval, args.sensor, "train")
    test = load(args.eval, args.sensor, "test")
    test_clean = load(args.eval, args.sensor, "test", clean=True)
    test_w = load(args.eval, args.sensor, "test_weights") if os.path.exists(
        os.path.join(args.eval, f"{args.sensor}_test_weights.npy")) else np.ones(test.shape[:3], np.float32)
    ref_path = os.path.join(args.train, f"{args.sensor}_reference.npy")
    reference = np.load(ref_path).astype(np.float32) if os.path.exists(ref_path) else None
    if args.head != "direct" and reference is None:
        sys.exit(f"representation_photometric.py: {ref_path} is missing (the photometric head "
                 "needs the reference frame; `tactfunc export` writes it for fixed-scale formats)")
    n, h, w, c = train.shape
    bytes_per_frame = 2 * args.latent_dim
    print(f"{args.sensor}: {n} train frames of {h}x{w}x{c}, {len(test)} test frames; "
          f"{bytes_per_frame} B per frame", flush=True)
    result = {"sensor": args.sensor, "head": args.head, "transform": args.transform,
              "width": args.width,
              "layers": args.layers, "latent_dim": args.latent_dim, "steps": args.steps,
              "bytes_per_frame": bytes_per_frame, "schedule": args.schedule,
              "trunk_rate": args.trunk_rate, "latent_rate": args.latent_rate,
              "fit_starts": args.fit_starts if args.transform else 1,
              "gradient": args.gradient}
    pca, pca_same_bits = pca_rows(eval_train, test, test_clean, test_w, bytes_per_frame)
    result.update(pca)
    print("PCA:", {k: result[k] for k in ("pca_float32", "pca_float16")}, flush=True)

    aspect = (w - 1) / max(h - 1, 1) if args.transform else 1.0
    coords = grid(h, w, aspect)
    native = None
    if args.markers == "native":
        if args.head == "direct" or not args.native_reference:
            sys.exit("representation_photometric.py: --markers native needs a photometric "
                     "head and --native-reference")
        with open(os.path.join(args.train, "export.json")) as f:
            scale = json.load(f)["sensors"][args.sensor]["frames"][0]["scale"]
        image = read_png(args.native_reference).astype(np.float64) / 255
        if c == 1 and image.shape[2] >= 3:
            image = (0.299 * image[..., 0] + 0.587 * image[..., 1] + 0.114 * image[..., 2])[..., None]
        native = image / scale
    result["markers"] = args.markers
    result["marker_model"] = args.marker_model
    trunk = Trunk(args.head, args.width, args.layers, args.latent_dim, c,
                  reference if reference is not None else np.zeros((h, w, c), np.float32),
                  transform=args.transform, aspect=aspect,
                  finite_differences=args.gradient == "differences", markers=args.markers,
                  native_reference=native, supersample=args.supersample,
                  marker_model=args.marker_model)
    start_latents = torch.zeros(n, args.latent_dim)
    if args.transform:
        start_latents[:, :3] = torch.from_numpy(moment_poses(train, coords))
        if args.transform == "translation":
            start_latents[:, 2] = 0
    latents = nn.Parameter(start_latents)
    targets = torch.from_numpy(train.reshape(n, h * w, c))
    # Invalid pixels (dropouts) hold 0 in the targets: they are left out of every loss.
    train_w_path = os.path.join(args.train, f"{args.sensor}_train_weights.npy")
    train_w = torch.from_numpy(np.load(train_w_path).reshape(n, h * w, 1)) if os.path.exists(
        train_w_path) else torch.ones(n, h * w, 1)
    opt = torch.optim.Adam([{"params": trunk.parameters(), "lr": args.trunk_rate},
                            {"params": [latents], "lr": args.latent_rate}])
    sched = None
    if args.schedule == "cosine":
        sched = torch.optim.lr_scheduler.LambdaLR(
            opt, lambda k: 0.1 + 0.45 * (1 + math.cos(math.pi * min(k, args.steps) / args.steps)))
    start = time.time()
    gen = torch.Generator().manual_seed(args.seed)
    if args.load_trunk:
        # A trunk trained with other --markers loads too: the sensor-resolution
        # reference is a buffer of this run's options, not a trained value.
        missing, unexpected = trunk.load_state_dict(torch.load(args.load_trunk), strict=False)
        if set(missing) - {"native"} or set(unexpected) - {"native"}:
            sys.exit(f"representation_photometric.py: {args.load_trunk} does not fit these "
                     f"options (missing {missing}, unexpected {unexpected})")
        print(f"loaded the trunk from {args.load_trunk}: no training", flush=True)
    for step in range(1, 0 if args.load_trunk else args.steps + 1):
        if args.markers == "native":
            trunk.markers = "bilinear" if step <= args.marker_warmup else "native"
        frames = torch.randint(0, n, (args.batch,), generator=gen)
        pix = torch.randint(0, h * w, (args.batch, args.pixels), generator=gen)
        x = coords[pix]
        y = torch.gather(targets[frames], 1, pix[..., None].expand(-1, -1, c))
        pred = trunk(x, latents[frames], create_graph=True)
        v = torch.gather(train_w[frames], 1, pix[..., None])
        loss = masked_mse(pred, y, v)
        opt.zero_grad()
        loss.backward()
        opt.step()
        if sched is not None:
            sched.step()
        if step % max(1, args.steps // 10) == 0:
            print(f"  step {step}/{args.steps}: train MSE {loss.item():.3e} "
                  f"({time.time() - start:.0f} s)", flush=True)
    trunk.markers = args.markers
    result["marker_warmup"] = args.marker_warmup
    if args.head != "direct":
        # The learned slope-to-displacement map (working pixels per unit slope): a
        # sheared or one-sided matrix says the head did not learn how the skin moves.
        result["marker_matrix"] = trunk.marker_matrix().detach().numpy().round(4).tolist()
    result["train_seconds"] = time.time() - start
    if args.save_trunk:
        torch.save(trunk.state_dict(), args.save_trunk + ".tmp")
        os.replace(args.save_trunk + ".tmp", args.save_trunk)

    # Fit every test latent to convergence with the trunk frozen: Adam on random pixel
    # subsets with a decaying rate, frames in chunks (memory), then scored on all pixels.
    for p in trunk.parameters():
        p.requires_grad_(False)
    m = len(test)
    test_t = torch.from_numpy(test.reshape(m, h * w, c))
    test_v = torch.from_numpy(test_w.reshape(m, h * w, 1))
    z_all = torch.zeros(m, args.latent_dim)
    start = time.time()
    chunk = 60
    starts = args.fit_starts if args.transform == "rigid" else 1
    for first, flip in ((f, k) for f in range(0, m, chunk) for k in range(starts)):
        idx = torch.arange(first, min(m, first + chunk))
        z0 = torch.zeros(len(idx), args.latent_dim)
        if args.transform:
            z0[:, :3] = torch.from_numpy(moment_poses(test[idx.numpy()], coords))
            z0[:, 2] += math.pi * flip
            if args.transform == "translation":
                z0[:, 2] = 0
        z = nn.Parameter(z0)
        fit_opt = torch.optim.Adam([z], lr=1e-2)
        sched = torch.optim.lr_scheduler.CosineAnnealingLR(fit_opt, args.fit_steps, 1e-4)
        for step in range(1, args.fit_steps + 1):
            pix = torch.randint(0, h * w, (len(idx), args.pixels), generator=gen)
            y = torch.gather(test_t[idx], 1, pix[..., None].expand(-1, -1, c))
            v = torch.gather(test_v[idx], 1, pix[..., None])
            loss = masked_mse(trunk(coords[pix], z, create_graph=True), y, v)
            fit_opt.zero_grad()
            loss.backward()
            fit_opt.step()
            sched.step()
        if flip == 0:
            z_all[idx] = z.detach()
        else:  # keep the start whose fit explains the frame's own (noisy) pixels better
            with torch.enable_grad():
                x = coords[None].expand(len(idx), -1, -1)
                def frame_loss(zz):
                    pred = trunk(x, zz, create_graph=False).detach()
                    return (((pred - test_t[idx]) ** 2) * test_v[idx]).sum((1, 2))
                better = frame_loss(z.detach()) < frame_loss(z_all[idx])
            z_all[idx[better]] = z.detach()[better]
            result["flipped_starts_kept"] = result.get("flipped_starts_kept", 0) + int(better.sum())
        print(f"  fitted {idx[-1].item() + 1}/{m} test latents: MSE {loss.item():.3e} "
              f"({time.time() - start:.0f} s)", flush=True)
    if args.refine_steps > 0:
        # Full-frame L-BFGS from the Adam fits: separable per frame, so chunks of frames
        # share one solve (the sum of their losses).
        adam_z = z_all.clone()
        for first in range(0, m, 20):
            idx = torch.arange(first, min(m, first + 20))
            x = coords[None].expand(len(idx), -1, -1)
            z = nn.Parameter(z_all[idx].clone())
            lbfgs = torch.optim.LBFGS([z], lr=1, max_iter=args.refine_steps,
                                      history_size=20, line_search_fn="strong_wolfe")

            def closure():
                lbfgs.zero_grad()
                pred = trunk(x, z, create_graph=True)
                loss = (((pred - test_t[idx]) ** 2) * test_v[idx]).sum()
                loss.backward()
                return loss

            with torch.enable_grad():
                lbfgs.step(closure)
            z_all[idx] = z.detach()
            print(f"  refined {idx[-1].item() + 1}/{m} test latents "
                  f"({time.time() - start:.0f} s)", flush=True)
        result["refine_steps"] = args.refine_steps
        result["refine_mean_change"] = float((z_all - adam_z).norm(dim=1).mean())
    result["fit_seconds"] = time.time() - start
    recon = render(trunk, coords, z_all.half().float(), test.shape)
    if args.refine_steps > 0:
        result["trunk_float16_before_refine"] = float(psnr_per_frame(
            render(trunk, coords, adam_z.half().float(), test.shape), test_clean, test_w).mean())
    result["trunk_float16"] = {
        "psnr_clean": float(psnr_per_frame(recon, test_clean, test_w).mean()),
        "psnr_noisy": float(psnr_per_frame(recon, test, test_w).mean())}
    tools = test_tools(args.eval, args.sensor, len(test))
    if tools is not None:
        # Per tool: which contacts hold the mean back, for the trunk and same-bits PCA.
        trunk_db = psnr_per_frame(recon, test_clean, test_w)
        pca_db = psnr_per_frame(pca_same_bits, test_clean, test_w)
        result["per_tool_psnr_clean"] = {
            t: {"trunk_float16": float(trunk_db[tools == t].mean()),
                "pca_float16": float(pca_db[tools == t].mean())}
            for t in sorted(set(tools))}
    result["margin_vs_pca_float32_clean"] = (result["trunk_float16"]["psnr_clean"] -
                                            result["pca_float32"]["psnr_clean"])
    result["margin_vs_pca_float16_clean"] = (result["trunk_float16"]["psnr_clean"] -
                                            result["pca_float16"]["psnr_clean"])
    print(json.dumps(result, indent=1), flush=True)
    if args.out:
        tmp = args.out + ".tmp"
        with open(tmp, "w") as f:
            json.dump(result, f, indent=1)
        os.replace(tmp, args.out)
        picture = os.path.splitext(args.out)[0] + ".png"
        write_sheet(picture, [test_clean, pca_same_bits, recon], count=6)
        print(f"wrote {args.out} and {picture} (rows: noise-free frame, PCA with the same "
              f"bits, this trunk; each frame scaled by its noise-free range)")


if __name__ == "__main__":
    main()
