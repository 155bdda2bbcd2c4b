"""What the representation study scripts share: tactfunc's PSNR on exported targets."""
import math

import numpy as np


def psnr_per_frame(pred, target, weights):
    """tactfunc's PSNR (estimation/data/trunk_targets.h) of each frame: the MSE over its
    valid pixels and channels, the peak the target's range over them (1 below 1e-9)."""
    out = []
    for p, t, w in zip(pred, target, weights):
        valid = w.reshape(-1) > 0
        tv = t.reshape(len(valid), -1)[valid]
        pv = p.reshape(len(valid), -1)[valid]
        r = float(tv.max() - tv.min()) if tv.size else 0.0
        r = r if r >= 1e-9 else 1.0
        mse = float(np.mean((pv.astype(np.float64) - tv.astype(np.float64)) ** 2))
        out.append(10 * math.log10(r * r / mse) if mse > 0 else float("inf"))
    return np.array(out)
