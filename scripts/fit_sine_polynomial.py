#!/usr/bin/env python3
"""Fits the odd polynomial of the float sine kernel (models/trunk/internal/fast_sincos_float.cc).

sin r ~ r + r z (c3 + c5 z + c7 z^2 + c9 z^3), z = r^2, for r in [-pi/2, pi/2], minimax in
relative error: least squares reweighted towards the largest errors until the error
equioscillates. Prints the coefficients as the kernel writes them (rounded to float) and
the relative error before rounding. Deterministic; needs numpy.

    python3 scripts/fit_sine_polynomial.py
"""
import numpy as np


def main():
    r = np.linspace(1e-4, np.pi / 2, 200001)
    z = r * r
    exact = np.sin(r)
    basis = np.stack([r * z * z**k for k in range(4)], axis=1)
    weights = np.ones_like(r)
    for _ in range(200):
        w = weights / exact
        coeffs, *_ = np.linalg.lstsq(basis * w[:, None], (exact - r) * w, rcond=None)
        error = (r + basis @ coeffs - exact) / exact
        weights = weights * (np.abs(error) / np.abs(error).max()) ** 0.3 + 1e-12
    for name, c in zip(["c3", "c5", "c7", "c9"], coeffs.astype(np.float32)):
        print(f"{name} = {float(c)!r}f")
    print(f"max relative error before rounding: {np.abs(error).max():.2e}")


if __name__ == "__main__":
    main()
