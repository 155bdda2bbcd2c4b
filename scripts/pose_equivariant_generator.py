#!/usr/bin/env python3
"""Design study: does rendering the pose as a coordinate transform of the trunk's input
lower the generator path's pose error floor?

The generator path (docs/POSES.md, "The generator path") renders a pose hypothesis as
trunk(p; h(tool, T, depth)): the pose enters only through the latent, and the generator
h has to learn how a translation or a turn of the contact moves it in latent space. The
alternative renders trunk(T^-1 p; h(tool, depth)): the contact is drawn in the object's
own frame and moved by geometry, so only the depth (and the sensor's departures from
equivariance, with --pose-features) is left for h. This script trains both layouts the
same way (trunk and generator jointly, same widths, steps and data) and measures, on
frames no training used:

  * rendering PSNR at the true pose;
  * the pose error floor: the pose fitted to each frame from the truth (the local
    minimum nearest the truth: what the model itself gets wrong, with no search);
  * the same from a start 0.8 mm and 8 degrees off (does the basin reach the truth?).

Inputs are `tactfunc export` folders of Soft Bubble frames with pose labels:

  tactfunc synth --out TRAIN --frames-per-tool 1000 --sensors bubble --seed 2
  tactfunc synth --out TEST --frames-per-tool 25 --sensors bubble --seed 90001
  tactfunc export --data TRAIN --model models/pretrained/default.tfm --out EX_TRAIN
  tactfunc export --data TEST --model models/pretrained/default.tfm --out EX_TEST
  python3 scripts/pose_equivariant_generator.py --train EX_TRAIN --test EX_TEST \
      --layout latent equivariant equivariant_pose

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
        self.h = torch.nn.Sequential(torch.nn.Linear(n_in, hidden), torch.nn.Tanh(),
                                     torch.nn.Linear(hidden, hidden), torch.nn.Tanh(),
                                     torch.nn.Linear(hidden, latent))
        self.mod = torch.nn.Linear(latent, width * layers)
        torch.nn.init.zeros_(self.mod.bias)
        self.lin = torch.nn.ModuleList([torch.nn.Linear(2 if i == 0 else width, width)
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


def fit_poses(model, tool_idx, start, coords, target, w, steps, lr):
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
    return pose.detach()


def pose_errors(fitted, truth, tools, tool_idx):
    dp = torch.linalg.norm(fitted[:, :2] - truth[:, :2], dim=1)
    yaw = []
    for i, t in enumerate(tool_idx.tolist()):
        n = SYMMETRY[tools[t]]
        if n == 0:
            continue
        period = 2 * math.pi / n
        e = (fitted[i, 2] - truth[i, 2]).item() % period
        yaw.append(min(e, period - e))
    yaw = np.degrees(np.array(yaw))
    return {"position_rmse_mm": float(torch.sqrt((dp ** 2).mean())),
            "position_median_mm": float(dp.median()),
            "yaw_rmse_deg": float(np.sqrt((yaw ** 2).mean())),
            "yaw_median_deg": float(np.median(yaw)),
            "yaw_within_5deg": float((yaw <= 5).mean())}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--train", required=True)
    ap.add_argument("--test", required=True)
    ap.add_argument("--layout", nargs="+", default=["latent", "equivariant", "equivariant_pose"],
                    choices=["latent", "equivariant", "equivariant_pose"])
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
    ev, ew, el = load(args.test)
    tools = sorted(SYMMETRY)
    rows, cols = tv.shape[1:]
    grid = pixel_grid(rows, cols)
    t_tool = torch.tensor([tools.index(l["tool"]) for l in tl])
    t_pose = poses_of(tl)
    rng = np.random.default_rng(args.seed + 1)
    keep = np.sort(rng.permutation(len(el))[:args.test_frames])
    e_tool = torch.tensor([tools.index(el[i]["tool"]) for i in keep])
    e_pose = poses_of([el[i] for i in keep])
    e_val = torch.tensor(ev[keep].reshape(len(keep), -1))
    e_w = torch.tensor(ew[keep].reshape(len(keep), -1))
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
        train_s = time.time() - start
        model.eval()
        for p in model.parameters():
            p.requires_grad_(False)
        with torch.no_grad():
            full = grid[None].expand(len(keep), -1, -1)
            render_psnr = psnr(model.render(e_tool, e_pose, full), e_val, e_w)
        coords = grid[fit_idx][None].expand(len(keep), -1, -1)
        target, w = e_val[:, fit_idx], e_w[:, fit_idx]
        floor = fit_poses(model, e_tool, e_pose, coords, target, w, args.fit_steps, 0.02)
        g = torch.Generator().manual_seed(args.seed + 2)
        ang = torch.rand(len(keep), generator=g) * 2 * math.pi
        off = e_pose.clone()
        off[:, 0] += 0.8 * torch.cos(ang)
        off[:, 1] += 0.8 * torch.sin(ang)
        off[:, 2] += math.radians(8) * torch.sign(torch.rand(len(keep), generator=g) - 0.5)
        off[:, 3] += 0.5
        moved = fit_poses(model, e_tool, off, coords, target, w, args.fit_steps, 0.05)
        results[layout] = {"render_psnr_db": render_psnr, "train_s": train_s,
                           "from_truth": pose_errors(floor, e_pose, tools, e_tool),
                           "from_offset": pose_errors(moved, e_pose, tools, e_tool)}
        print(json.dumps({layout: results[layout]}, indent=1), flush=True)
    if args.out:
        tmp = args.out + ".tmp"
        with open(tmp, "w") as f:
            json.dump({"args": vars(args), "results": results}, f, indent=1)
        os.replace(tmp, args.out)


if __name__ == "__main__":
    main()
