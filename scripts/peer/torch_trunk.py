#!/usr/bin/env python3
# Copyright 2026 The tactfunc Authors.
"""tactfunc's trunk workloads written in PyTorch, for side-by-side timing on the CPU.

The same latent-modulated SIREN as models/trunk/latent_modulated_siren.h, float32, with
SIREN's initialisation (the values do not change the speed):

    gamma   = A z + c                              (one linear map of the latent)
    h_0     = x                                    (2 pixel coordinates in (-1, 1))
    h_{l+1} = sin(omega_0 (W_l h_l + b_l + gamma_l))   l = 0 .. L-1, omega_0 = 30
    y       = W_out h_L + b_out                    (C channels)

(tactfunc's optional linear readout branch is left out: it is off by default and in
every timed trunk.) The loss is tactfunc's weighted per-pixel MSE,
sum_j w_j ||y_j - t_j||^2 / (C sum_j w_j), and the inner loop is tactfunc's meta-SGD,
z <- z - alpha * d/dz [loss + lambda ||z||^2] from z = 0 with lambda = 1e-5.

Subcommands (each prints one JSON line of medians, min and max over --repeats):

  fit        a meta_sgd:K fit of one whole frame on one thread, as tactfunc's LatentFitter
             does it: "core" times the K steps; "full" adds what the whole fit also
             does -- the frame's coordinate grid, the objective at the start latent and
             at z_K (data term 1/2 sum w (y - t)^2 / sigma^2 plus 1/2 ||z||^2) with the
             frame's PSNR: at the start from the first step's outputs (as tactfunc does),
             at z_K from one whole-frame forward pass.
  meta-step  one second-order meta-training step, batched as a PyTorch user writes it: a
             batch of frames, a random subset of pixels of each, K inner steps with
             create_graph=True, the outer loss after them, backward through the inner
             loop into the trunk and the rates alpha, one Adam step, alpha clipped to [0, 1].
  flops      the matrix-product FLOPs of both workloads as PyTorch's profiler counts
             them (aten::mm / addmm / bmm / matmul), beside the analytic count of
             reverse-mode autograd.

--products bf16 runs every matrix product with its operands in bfloat16 the way a
PyTorch user asks for it on the CPU, under torch.autocast("cpu", dtype=torch.bfloat16)
(oneDNN's bfloat16 products where the CPU has them), with the products' results taken
back to float32 before the sines, so that, as in tactfunc's --products bf16, only the
products run in bfloat16.

The program never imports anything outside the standard library and torch.
"""
import argparse
import json
import math
import statistics
import sys
import time

import torch

OMEGA_0 = 30.0
LATENT_L2 = 1e-5  # tactfunc's inner-loop lambda (TrunkTrainer's default)


class Trunk(torch.nn.Module):
    """The latent-modulated SIREN; coords (..., P, 2), z (..., d) -> (..., P, C)."""

    def __init__(self, width, layers, latent, channels):
        super().__init__()
        self.width = width
        self.hidden = torch.nn.ModuleList(
            [torch.nn.Linear(2, width)] + [torch.nn.Linear(width, width) for _ in range(layers - 1)])
        self.modulation = torch.nn.Linear(latent, layers * width)  # A and c
        self.out = torch.nn.Linear(width, channels)
        with torch.no_grad():
            # tactfunc's initialisation: the first layer U(-1/2, 1/2) (1 / fan_in), the
            # others U(-sqrt(6/width)/omega_0, +), A U(-sqrt(6/d)/omega_0, +), c = 0.
            self.hidden[0].weight.uniform_(-0.5, 0.5)
            self.hidden[0].bias.uniform_(-0.5, 0.5)
            bound = math.sqrt(6.0 / width) / OMEGA_0
            for layer in list(self.hidden[1:]) + [self.out]:
                layer.weight.uniform_(-bound, bound)
                layer.bias.uniform_(-bound, bound)
            self.modulation.weight.uniform_(-math.sqrt(6.0 / latent) / OMEGA_0,
                                            math.sqrt(6.0 / latent) / OMEGA_0)
            self.modulation.bias.zero_()

    def forward(self, coords, z):
        # .float() is the identity on float32 tensors; under --products bf16 it takes
        # each product's bfloat16 result back to float32.
        shifts = self.modulation(z).float().unsqueeze(-2).split(self.width, dim=-1)
        h = coords
        for layer, shift in zip(self.hidden, shifts):
            h = torch.sin(OMEGA_0 * (layer(h).float() + shift))
        return self.out(h).float()


def grid(rows, cols):
    """tactfunc's pixel-centre coordinates, pixel r * cols + c -> (x0 by column, x1 by row)."""
    x0 = (torch.arange(cols, dtype=torch.float32) + 0.5) * (2.0 / cols) - 1.0
    x1 = (torch.arange(rows, dtype=torch.float32) + 0.5) * (2.0 / rows) - 1.0
    return torch.stack([x0.repeat(rows), x1.repeat_interleave(cols)], dim=1)


def weighted_mse(y, targets, weights):
    """Per frame: sum_j w_j ||y_j - t_j||^2 / (C sum_j w_j); y, targets (..., P, C)."""
    squared = ((y - targets) ** 2).sum(-1)
    return (weights * squared).sum(-1) / (y.shape[-1] * weights.sum(-1))


def generated_frame(trunk, coords, generator):
    """A frame the trunk makes from a random latent (0.3 N(0, 1)) plus 0.01 noise."""
    with torch.no_grad():
        latent = 0.3 * torch.randn(trunk.modulation.in_features, generator=generator)
        values = trunk(coords, latent)
        return values + 0.01 * torch.randn(values.shape, generator=generator)


def spread(prefix, values):
    return {prefix + "median": statistics.median(values), prefix + "min": min(values),
            prefix + "max": max(values)}


def macs_per_pixel(width, layers, channels):
    """Multiply-adds per pixel of one forward pass's matrix products: first, hidden, out."""
    return 2 * width, (layers - 1) * width * width, width * channels


def analytic_flops(args, pixels_per_frame):
    """Matrix-product FLOPs of reverse-mode autograd with stored activations (the PyTorch
    way): a latent gradient is a forward pass and one transposed product per layer but
    the first; the outer backward through each inner step costs first + 4 (hidden + out)
    multiply-adds per pixel (the forward pass's weight and input products, and both
    products of each transposed product)."""
    first, hidden, out = macs_per_pixel(args.width, args.layers, args.channels)
    grad_z = first + 2 * hidden + 2 * out
    grad_theta = 2 * first + 3 * hidden + 3 * out
    double_backward = first + 4 * hidden + 4 * out
    n = args.rows * args.cols
    fit_core = 2.0 * args.steps * n * grad_z
    return {
        "fit_core_gemm_gflop": fit_core / 1e9,
        "fit_full_gemm_gflop":
            (fit_core + 2.0 * (1 if args.steps > 0 else 2) * n * (first + hidden + out)) / 1e9,
        "meta_step_gemm_gflop": 2.0 * args.batch * pixels_per_frame *
        (args.steps * grad_z + grad_theta + args.steps * double_backward) / 1e9,
    }


def make_trunk(args):
    torch.manual_seed(1)
    return Trunk(args.width, args.layers, args.latent, args.channels)


# ---- fit ----------------------------------------------------------------------------

def fit_steps(trunk, coords, targets, weights, alpha, z, steps, start_outputs=None):
    """The K meta-SGD steps from z (gradients w.r.t. z only). If start_outputs is a list,
    the first step's outputs (the trunk at the start z) are appended to it."""
    for k in range(steps):
        z = z.detach().requires_grad_(True)
        y = trunk(coords, z)
        if k == 0 and start_outputs is not None:
            start_outputs.append(y.detach())
        loss = weighted_mse(y, targets, weights) + LATENT_L2 * (z * z).sum()
        (g,) = torch.autograd.grad(loss, z)
        z = z - alpha * g
    return z.detach()


def objective(trunk, coords, targets, weights, z, sigma, sigma_z=1.0):
    """The fit's cost at z and the frame's PSNR, from one whole-frame forward pass."""
    with torch.no_grad():
        return cost_and_psnr(trunk(coords, z), targets, weights, z, sigma, sigma_z)


def cost_and_psnr(y, targets, weights, z, sigma, sigma_z=1.0):
    """The fit's cost at z and the frame's PSNR from the trunk's outputs y at z."""
    with torch.no_grad():
        squared = weights * ((y - targets) ** 2).sum(-1)
        cost = 0.5 * squared.sum() / sigma ** 2 + 0.5 * (z * z).sum() / sigma_z ** 2
        valid = targets[weights > 0]
        peak = (valid.max() - valid.min()).item()
        mse = squared.sum().item() / (valid.numel())
        psnr = 10 * math.log10(peak * peak / mse) if mse > 0 else math.inf
    return cost.item(), psnr


def full_fit(trunk, rows, cols, targets, weights, alpha, steps, sigma=0.01):
    """As tactfunc's meta_sgd:K fit: the start's cost and PSNR from the first step's own
    forward pass (a pass of its own when K = 0), the final ones from one pass at z_K."""
    coords = grid(rows, cols)
    z0 = torch.zeros(alpha.shape[0])
    first = []
    z = fit_steps(trunk, coords, targets, weights, alpha, z0, steps, first)
    if first:
        cost_and_psnr(first[0], targets, weights, z0, sigma)
    else:
        objective(trunk, coords, targets, weights, z0, sigma)
    _, psnr = objective(trunk, coords, targets, weights, z, sigma)
    return z, psnr


def fit_setup(args):
    """The frozen trunk, the frame's grid, a generated frame, its weights and alpha = 1."""
    trunk = make_trunk(args).requires_grad_(False)
    coords = grid(args.rows, args.cols)
    targets = generated_frame(trunk, coords, torch.Generator().manual_seed(5))
    return trunk, coords, targets, torch.ones(coords.shape[0]), torch.ones(args.latent)


def run_fit(args):
    trunk, coords, targets, weights, alpha = fit_setup(args)
    full_fit(trunk, args.rows, args.cols, targets, weights, alpha, args.steps)  # warm-up
    core_ms, full_ms, psnr = [], [], math.nan
    for _ in range(args.repeats):
        start = time.perf_counter()
        fit_steps(trunk, coords, targets, weights, alpha, torch.zeros(args.latent), args.steps)
        core_ms.append(1e3 * (time.perf_counter() - start))
        start = time.perf_counter()
        _, psnr = full_fit(trunk, args.rows, args.cols, targets, weights, alpha, args.steps)
        full_ms.append(1e3 * (time.perf_counter() - start))
    out = {"workload": "fit", "pixels": args.rows * args.cols, "psnr": psnr,
           "core_ms": core_ms, "full_ms": full_ms}
    out.update(spread("core_ms_", core_ms))
    out.update(spread("full_ms_", full_ms))
    return out


# ---- meta-step ------------------------------------------------------------------------

class MetaTrainer:
    """One outer step of second-order meta-SGD training, batched over frames."""

    def __init__(self, args):
        self.args = args
        self.trunk = make_trunk(args)
        coords = grid(args.rows, args.cols)
        generator = torch.Generator().manual_seed(100)
        self.grid = coords
        self.frames = torch.stack([generated_frame(self.trunk, coords, generator)
                                   for _ in range(args.batch)])  # (F, N, C)
        self.alpha = torch.nn.Parameter(torch.ones(args.latent))
        self.optimizer = torch.optim.Adam(
            [{"params": self.trunk.parameters(), "lr": 3e-4},
             {"params": [self.alpha], "lr": 1e-3}], betas=(0.9, 0.999), eps=1e-8)
        n = coords.shape[0]
        self.pixels = args.pixels if 0 < args.pixels < n else n

    def batch(self):
        """The batch's frames (one epoch's permutation) and a random pixel subset of each."""
        n = self.grid.shape[0]
        frames = torch.randperm(self.frames.shape[0])[:self.args.batch]
        pixels = torch.stack([torch.randperm(n)[:self.pixels] for _ in range(self.args.batch)])
        coords = self.grid[pixels]                        # (B, P, 2)
        targets = self.frames[frames.unsqueeze(1), pixels]  # (B, P, C)
        weights = torch.ones(pixels.shape)
        return coords, targets, weights

    def step(self):
        coords, targets, weights = self.batch()
        z = torch.zeros(self.args.batch, self.args.latent, requires_grad=True)
        for _ in range(self.args.steps):
            inner = weighted_mse(self.trunk(coords, z), targets, weights) + \
                LATENT_L2 * (z * z).sum(-1)
            (g,) = torch.autograd.grad(inner.sum(), z, create_graph=True)
            z = z - self.alpha * g
        outer = weighted_mse(self.trunk(coords, z), targets, weights).mean()
        self.optimizer.zero_grad()
        outer.backward()
        self.optimizer.step()
        with torch.no_grad():
            self.alpha.clamp_(0.0, 1.0)
        return outer.item()


def run_meta_step(args):
    trainer = MetaTrainer(args)
    trainer.step()  # warm-up
    ms = []
    for _ in range(args.repeats):
        start = time.perf_counter()
        trainer.step()
        ms.append(1e3 * (time.perf_counter() - start))
    out = {"workload": "meta-step", "pixels": trainer.pixels, "ms": ms}
    out.update(spread("ms_", ms))
    return out


# ---- flops ------------------------------------------------------------------------------

GEMM_OPS = ("aten::mm", "aten::addmm", "aten::bmm", "aten::baddbmm")


def profiled_gemm_flops(fn):
    """FLOPs of the matrix products PyTorch's profiler counts while fn() runs (its
    element-wise counts, aten::mul and aten::add, are left out)."""
    from torch.profiler import profile, ProfilerActivity
    with profile(activities=[ProfilerActivity.CPU], with_flops=True) as prof:
        fn()
    return sum(e.flops for e in prof.key_averages() if e.key in GEMM_OPS and e.flops)


def run_flops(args):
    trunk, coords, targets, weights, alpha = fit_setup(args)
    trainer = MetaTrainer(args)
    out = {"workload": "flops"}
    out["profiled_fit_core_gemm_gflop"] = profiled_gemm_flops(
        lambda: fit_steps(trunk, coords, targets, weights, alpha, torch.zeros(args.latent),
                          args.steps)) / 1e9
    out["profiled_fit_full_gemm_gflop"] = profiled_gemm_flops(
        lambda: full_fit(trunk, args.rows, args.cols, targets, weights, alpha, args.steps)) / 1e9
    out["profiled_meta_step_gemm_gflop"] = profiled_gemm_flops(trainer.step) / 1e9
    out.update(analytic_flops(args, trainer.pixels))
    return out


# ---- main ---------------------------------------------------------------------------------

def blas_libraries():
    """The BLAS / LAPACK shared objects mapped into this process (Linux)."""
    try:
        with open("/proc/self/maps") as maps:
            names = {line.split()[-1] for line in maps if "/" in line}
    except OSError:
        return []
    keys = ("blas", "lapack", "atlas", "mkl")
    return sorted(n for n in names if any(k in n.rsplit("/", 1)[-1].lower() for k in keys))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("workload", choices=["fit", "meta-step", "flops"])
    parser.add_argument("--width", type=int, default=64, help="units per sine layer")
    parser.add_argument("--layers", type=int, default=3, help="sine layers L")
    parser.add_argument("--latent", type=int, default=64, help="latent dimension d")
    parser.add_argument("--channels", type=int, default=1, help="output channels C")
    parser.add_argument("--rows", type=int, default=70, help="frame rows")
    parser.add_argument("--cols", type=int, default=88, help="frame columns")
    parser.add_argument("--steps", type=int, default=3, help="meta-SGD steps K")
    parser.add_argument("--batch", type=int, default=32, help="frames per meta-training step")
    parser.add_argument("--pixels", type=int, default=512,
                        help="random pixels per frame per meta-training step (0 = all)")
    parser.add_argument("--threads", type=int, default=1, help="torch.set_num_threads")
    parser.add_argument("--repeats", type=int, default=20, help="timed repetitions")
    parser.add_argument("--products", choices=["float", "bf16"], default="float",
                        help="precision of the matrix products (bf16: torch.autocast)")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    torch.set_num_interop_threads(1)
    run = {"fit": run_fit, "meta-step": run_meta_step, "flops": run_flops}[args.workload]
    out = {"impl": "pytorch", "torch": torch.__version__, "threads": torch.get_num_threads(),
           "width": args.width, "layers": args.layers, "latent": args.latent,
           "channels": args.channels, "rows": args.rows, "cols": args.cols,
           "steps": args.steps, "batch": args.batch, "repeats": args.repeats,
           "products": args.products}
    with torch.autocast("cpu", dtype=torch.bfloat16, enabled=args.products == "bf16"):
        out.update(run(args))
    out["blas"] = blas_libraries()
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
