#!/usr/bin/env python3
"""Design study: does rendering the pose as a coordinate transform of the trunk's input
lower the generator path's pose error floor?

The generator path (docs/POSES.md, "The generator path") renders a pose hypothesis as
trunk(p; h(tool, T, depth)): the pose enters only through the latent, and the generator
h has to learn how a translation or a turn of the contact moves it in latent space. The
alternative renders trunk(T^-1 p; h(tool, depth)): the contact is drawn in the object's
own frame and moved by geometry, so only the depth is left for h (layout `equivariant`;
`equivariant_pose` also hands h the pose). The dome of the membrane is fixed in the
sensor's frame, not the object's: layout `both_frames` gives the trunk both T^-1 p and p
(four inputs), so that it can draw where the face meets the dome while the pose still
moves the contact by geometry. This script trains the layouts the same way (trunk and
generator jointly, same widths, steps and data) and measures, on frames no training
used:

  * rendering PSNR at the true pose;
  * the pose error floor: the pose fitted to each frame from the truth (the local
    minimum nearest the truth: what the model itself gets wrong, with no search);
  * the same from a start 0.8 mm and 8 degrees off (does the basin reach the truth?);
  * ranking against the symmetry-turned pose: each frame of a tool with a symmetry order
    n > 0 is also fitted from its true pose turned by half the symmetry period (a
    quarter turn for n = 2, as the search's wrong modes of `lines5`), and counted
    misranked when that fit ends 30 degrees or more from the truth (modulo symmetry)
    with a lower loss than the fit from the truth: the model itself would put the
    heaviest mode there. Counted over all such frames and over those pressed less than
    6 mm deep. `--test-tools lines5` scores one tool's frames.

Inputs are `tactfunc export` folders of Soft Bubble frames with pose labels:

  tactfunc synth --out TRAIN --frames-per-tool 1000 --sensors bubble --seed 2
  tactfunc synth --out TEST --frames-per-tool 25 --sensors bubble --seed 90001
  tactfunc export --data TRAIN --model models/pretrained/default.tfm --out EX_TRAIN
  tactfunc export --data TEST --model models/pretrained/default.tfm --out EX_TEST
  python3 scripts/pose_equivariant_generator.py --train EX_TRAIN --test EX_TEST \
      --layout latent equivariant equivariant_pose both_frames

and for the ranking of shallow `lines5` presses a set of that tool alone:

  tactfunc synth --out L5 --frames-per-tool 400 --tools lines5 --sensors bubble --seed 90002
  tactfunc export --data L5 --model models/pretrained/default.tfm --out EX_L5
  python3 scripts/pose_equivariant_generator.py --train EX_TRAIN --test EX_TEST EX_L5 \
      --test-frames 400 --layout latent both_frames

(several --test folders share one training per layout; --test-frames caps each).

Needs numpy and torch (CPU). Deterministic for --seed at a fixed thread count.
"""
import argparse
import json
import math
import os
import sys
import time

import numpy as np
import torch

# Symmetry orders of the simulator's tools (models/simulator/tool.cc).
SYMMETRY = {"lines2_30": 2, "lines2_60": 2, "lines2_90": 4, "lines3_20": 1, "lines3_40": 1,
            "lines5": 2, "rod": 2, "hemisphere": 0, "triangle": 3, "square": 4,
            "l_shape": 1, "half_disc": 1}
# Soft Bubble camera: 140 x 175 pixels of 0.45 mm, area-resized to the format's grid.
RAW_ROWS, RAW_COLS, RAW_PITCH_MM = 140, 175, 0.45
COORD_SCALE_MM = 20.0  # trunk input = millimetres / this


def load(folder):
    meta = json.load(open(os.path.join(folder, "export.json")))
    s = meta["sensors"]["bubble"]
    values = np.load(os.path.join(folder, s["files"]["values"]))[..., 0]
    weights = np.load(os.path.join(folder, s["files"]["weights"]))
    labels = [f["label"] for f in s["frames"]]
    if any(l is None for l in labels):
        sys.exit(f"{folder}: every frame needs a pose label")
    return values.astype(np.float32), weights.astype(np.float32), labels


def pixel_grid(rows, cols):
    px = RAW_COLS * RAW_PITCH_MM / cols
    py = RAW_ROWS * RAW_PITCH_MM / rows
    c = (np.arange(cols) + 0.5 - 0.5 * cols) * px
    r = (0.5 * rows - np.arange(rows) - 0.5) * py
    x, y = np.meshgrid(c, r)
    return torch.tensor(np.stack([x.ravel(), y.ravel()], 1), dtype=torch.float32)  # mm


class Model(torch.nn.Module):
    """SIREN trunk with shift modulations from a latent, and a generator MLP."""

    def __init__(self, tools, layout, width, layers, latent, hidden, omega0):
        super().__init__()
        self.tools, self.layout, self.omega0 = tools, layout, omega0
        pose_in = layout in ("latent", "equivariant_pose")
        n_in = len(tools) + 1 + (2 + 8 if pose_in else 0)
        n_coords = 4 if layout == "both_frames" else 2
        self.h = torch.nn.Sequential(torch.nn.Linear(n_in, hidden), torch.nn.Tanh(),
                                     torch.nn.Linear(hidden, hidden), torch.nn.Tanh(),
                                     torch.nn.Linear(hidden, latent))
        self.mod = torch.nn.Linear(latent, width * layers)
        torch.nn.init.zeros_(self.mod.bias)
        self.lin = torch.nn.ModuleList([torch.nn.Linear(n_coords if i == 0 else width, width)
                                        for i in range(layers)])
        with torch.no_grad():
            for i, l in enumerate(self.lin):
                bound = 1.0 / 2 if i == 0 else math.sqrt(6.0 / width) / omega0
                l.weight.uniform_(-bound, bound)
                l.bias.uniform_(-bound, bound)
        self.out = torch.nn.Linear(width, 1)
        self.width, self.layers = width, layers

    def features(self, tool_idx, pose):
        """pose: (B, 4) = x mm, y mm, yaw rad, depth mm."""
        b = pose.shape[0]
        onehot = torch.zeros(b, len(self.tools))
        onehot[torch.arange(b), tool_idx] = 1
        f = [onehot, ((pose[:, 3] - 9.0) / 4.0)[:, None]]
        if self.layout in ("latent", "equivariant_pose"):
            n = torch.tensor([SYMMETRY[self.tools[t]] for t in tool_idx.tolist()],
                             dtype=torch.float32)
            f += [pose[:, :2] / 5.0]
            for k in range(1, 5):
                f += [torch.stack([torch.cos(k * n * pose[:, 2]) * (n > 0),
                                   torch.sin(k * n * pose[:, 2]) * (n > 0)], 1)]
        return torch.cat(f, 1)

    def render(self, tool_idx, pose, coords):
        """coords: (B, P, 2) mm in the sensor frame; returns (B, P)."""
        shifts = self.mod(self.h(self.features(tool_idx, pose))).view(-1, self.layers, self.width)
        if self.layout == "latent":
            u = coords
        else:  # object frame: R(-yaw) (p - t)
            d = coords - pose[:, None, :2]
            c, s = torch.cos(pose[:, 2])[:, None], torch.sin(pose[:, 2])[:, None]
            u = torch.stack([c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1]], -1)
            if self.layout == "both_frames":
                u = torch.cat([u, coords], -1)
        h = u / COORD_SCALE_MM
        for i, l in enumerate(self.lin):
            h = torch.sin(self.omega0 * l(h) + shifts[:, i][:, None, :])
        return self.out(h)[..., 0]


def poses_of(labels):
    return torch.tensor([[l["x_m"] * 1e3, l["y_m"] * 1e3, l["yaw_rad"], l["depth_m"] * 1e3]
                         for l in labels], dtype=torch.float32)


def psnr(pred, target, w):
    mse = ((pred - target) ** 2 * w).sum(1) / w.sum(1)
    return (-10 * torch.log10(mse.clamp_min(1e-12))).mean().item()


def fit_poses(model, tool_idx, start, coords, target, w, steps, lr, chunk=32):
    """Fits each frame's pose from `start`; chunks of frames are fitted one after another
    (each frame's pose sees only its own frame's loss, so the result is the same up to
    rounding; all 700 frames of the two test sets at once ran several times slower)."""
    poses, losses = [], []
    for b in range(0, len(tool_idx), chunk):
        e = slice(b, b + chunk)
        p, l = fit_pose_chunk(model, tool_idx[e], start[e], coords[e], target[e], w[e], steps, lr)
        poses.append(p)
        losses.append(l)
    return torch.cat(poses), torch.cat(losses)


def fit_pose_chunk(model, tool_idx, start, coords, target, w, steps, lr):
    pose = start.clone().requires_grad_(True)
    scale = torch.tensor([1.0, 1.0, 0.05, 1.0])  # mm, mm, rad, mm per unit step
    opt = torch.optim.Adam([pose], lr=lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, steps, eta_min=lr * 0.02)
    for _ in range(steps):
        opt.zero_grad()
        pred = model.render(tool_idx, pose, coords)
        loss = (((pred - target) ** 2 * w).sum(1) / w.sum(1)).sum() * 1e3
        loss.backward()
        pose.grad *= scale
        opt.step()
        sched.step()
        with torch.no_grad():
            pose[:, 3].clamp_(1.5, 17.5)
    with torch.no_grad():
        pred = model.render(tool_idx, pose, coords)
        loss = ((pred - target) ** 2 * w).sum(1) / w.sum(1)
    return pose.detach(), loss


def yaw_error_deg(fitted_yaw, true_yaw, n):
    """Yaw error modulo the symmetry order n (> 0), degrees."""
    period = 2 * math.pi / n
    e = (fitted_yaw - true_yaw) % period
    return math.degrees(min(e, period - e))


def ranking(floor, floor_loss, turned, turned_loss, truth, tools, tool_idx):
    """Frames whose fit from the turned pose ends >= 30 deg off with a lower loss."""
    counts = {"frames": 0, "misranked": 0, "shallow_frames": 0, "shallow_misranked": 0}
    for i, t in enumerate(tool_idx.tolist()):
        n = SYMMETRY[tools[t]]
        if n == 0:
            continue
        wrong = (yaw_error_deg(turned[i, 2].item(), truth[i, 2].item(), n) >= 30 and
                 turned_loss[i].item() < floor_loss[i].item())
        shallow = truth[i, 3].item() < 6.0
        counts["frames"] += 1
        counts["misranked"] += int(wrong)
        counts["shallow_frames"] += int(shallow)
        counts["shallow_misranked"] += int(wrong and shallow)
    return counts


def pose_errors(fitted, truth, tools, tool_idx):
    dp = torch.linalg.norm(fitted[:, :2] - truth[:, :2], dim=1)
    yaw = []
    for i, t in enumerate(tool_idx.tolist()):
        n = SYMMETRY[tools[t]]
        if n == 0:
            continue
        yaw.append(yaw_error_deg(fitted[i, 2].item(), truth[i, 2].item(), n))
    yaw = np.array(yaw)
    return {"position_rmse_mm": float(torch.sqrt((dp ** 2).mean())),
            "position_median_mm": float(dp.median()),
            "yaw_rmse_deg": float(np.sqrt((yaw ** 2).mean())),
            "yaw_median_deg": float(np.median(yaw)),
            "yaw_within_5deg": float((yaw <= 5).mean())}


def test_set(folder, args, tools, rng):
    """The test frames of one exported folder (at most --test-frames, --test-tools only)."""
    ev, ew, el = load(folder)
    candidates = np.array([i for i, l in enumerate(el)
                           if not args.test_tools or l["tool"] in args.test_tools])
    if len(candidates) == 0:
        sys.exit(f"{folder}: no test frame of the tools {args.test_tools}")
    keep = np.sort(candidates[rng.permutation(len(candidates))[:args.test_frames]])
    return {"tool": torch.tensor([tools.index(el[i]["tool"]) for i in keep]),
            "pose": poses_of([el[i] for i in keep]),
            "values": torch.tensor(ev[keep].reshape(len(keep), -1)),
            "weights": torch.tensor(ew[keep].reshape(len(keep), -1))}


def evaluate(model, test, grid, fit_idx, tools, args):
    """Rendering PSNR, pose floors and the ranking test on one test set."""
    e_tool, e_pose, e_val, e_w = test["tool"], test["pose"], test["values"], test["weights"]
    n = len(e_tool)
    with torch.no_grad():
        full = grid[None].expand(n, -1, -1)
        render_psnr = psnr(model.render(e_tool, e_pose, full), e_val, e_w)
    coords = grid[fit_idx][None].expand(n, -1, -1)
    target, w = e_val[:, fit_idx], e_w[:, fit_idx]
    floor, floor_loss = fit_poses(model, e_tool, e_pose, coords, target, w, args.fit_steps, 0.02)
    g = torch.Generator().manual_seed(args.seed + 2)
    ang = torch.rand(n, generator=g) * 2 * math.pi
    off = e_pose.clone()
    off[:, 0] += 0.8 * torch.cos(ang)
    off[:, 1] += 0.8 * torch.sin(ang)
    off[:, 2] += math.radians(8) * torch.sign(torch.rand(n, generator=g) - 0.5)
    off[:, 3] += 0.5
    moved, _ = fit_poses(model, e_tool, off, coords, target, w, args.fit_steps, 0.05)
    # Half the symmetry period (a half turn for tools without symmetry, n = 1).
    half = torch.tensor([math.pi / SYMMETRY[tools[t]] if SYMMETRY[tools[t]] > 0 else 0.0
                         for t in e_tool.tolist()])
    turned_start = e_pose.clone()
    turned_start[:, 2] += half
    turned, turned_loss = fit_poses(model, e_tool, turned_start, coords, target, w,
                                    args.fit_steps, 0.02)
    return {"frames": n, "render_psnr_db": render_psnr,
            "from_truth": pose_errors(floor, e_pose, tools, e_tool),
            "from_offset": pose_errors(moved, e_pose, tools, e_tool),
            "turned": ranking(floor, floor_loss, turned, turned_loss, e_pose, tools, e_tool)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--train", required=True)
    ap.add_argument("--test", required=True, nargs="+", help="one or more exported folders")
    ap.add_argument("--layout", nargs="+", default=["latent", "equivariant", "equivariant_pose"],
                    choices=["latent", "equivariant", "equivariant_pose", "both_frames"])
    ap.add_argument("--test-tools", nargs="+", help="score only these tools' test frames")
    ap.add_argument("--steps", type=int, default=4000)
    ap.add_argument("--batch-frames", type=int, default=32)
    ap.add_argument("--batch-pixels", type=int, default=768)
    ap.add_argument("--width", type=int, default=64)
    ap.add_argument("--layers", type=int, default=3)
    ap.add_argument("--latent", type=int, default=64)
    ap.add_argument("--hidden", type=int, default=256)
    ap.add_argument("--omega0", type=float, default=30.0)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--fit-pixels", type=int, default=1024)
    ap.add_argument("--fit-steps", type=int, default=300)
    ap.add_argument("--test-frames", type=int, default=240)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", help="JSON file for the results")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)

    tv, tw, tl = load(args.train)
    tools = sorted(SYMMETRY)
    rows, cols = tv.shape[1:]
    grid = pixel_grid(rows, cols)
    t_tool = torch.tensor([tools.index(l["tool"]) for l in tl])
    t_pose = poses_of(tl)
    rng = np.random.default_rng(args.seed + 1)
    tests = {folder: test_set(folder, args, tools, rng) for folder in args.test}
    tv = torch.tensor(tv.reshape(len(tv), -1))
    tw = torch.tensor(tw.reshape(len(tw), -1))
    n_pix = grid.shape[0]
    fit_idx = torch.tensor(np.sort(rng.permutation(n_pix)[:args.fit_pixels]))

    results = {}
    for layout in args.layout:
        torch.manual_seed(args.seed)
        gen = torch.Generator().manual_seed(args.seed)
        model = Model(tools, layout, args.width, args.layers, args.latent, args.hidden,
                      args.omega0)
        opt = torch.optim.Adam(model.parameters(), lr=args.lr)
        sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, args.steps, eta_min=args.lr * 0.05)
        start = time.time()
        for step in range(args.steps):
            fi = torch.randint(len(tv), (args.batch_frames,), generator=gen)
            pi = torch.randint(n_pix, (args.batch_frames, args.batch_pixels), generator=gen)
            coords = grid[pi]
            target = torch.gather(tv[fi], 1, pi)
            w = torch.gather(tw[fi], 1, pi)
            pred = model.render(t_tool[fi], t_pose[fi], coords)
            loss = ((pred - target) ** 2 * w).sum() / w.sum()
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            if step % 500 == 0 or step == args.steps - 1:
                print(f"[{layout}] step {step}/{args.steps} loss {loss.item():.3e} "
                      f"({time.time() - start:.0f} s)", file=sys.stderr, flush=True)
        results[layout] = {"train_s": time.time() - start}
        model.eval()
        for p in model.parameters():
            p.requires_grad_(False)
        for folder, test in tests.items():
            results[layout][folder] = evaluate(model, test, grid, fit_idx, tools, args)
        print(json.dumps({layout: results[layout]}, indent=1), flush=True)
    if args.out:
        tmp = args.out + ".tmp"
        with open(tmp, "w") as f:
            json.dump({"args": vars(args), "results": results}, f, indent=1)
        os.replace(tmp, args.out)


if __name__ == "__main__":
    main()
