#!/usr/bin/env python3
"""How much a marker pattern loses when it is moved on the resized reference instead of on
the sensor's own pixels: a bound on the photometric head's marker term, without any
trunk.

An optical sensor's markers are dots about a working pixel wide (GelSlim: radius 0.22 mm,
pitch 1.2 mm at 0.07 mm per sensor pixel; the trunk works on a 4x area resize). The skin
moves them by a fraction of a pixel. The photometric prototype
(scripts/representation_photometric.py, `--markers bilinear|bicubic`) renders the moved
markers by resampling the RESIZED reference; the sensor images them moved at its own
resolution and then resized. This script draws the GelSlim's marker grid as the
simulator does (docs/SIMULATOR.md: dark dots, 70 % darkness, one-pixel antialiasing, a
grey of 0.53), moves it by a smooth radial displacement field whose largest shift is S
working pixels, and scores the marker-only difference frame each way against the truth
(moved at sensor resolution, then area-resized), as tactfunc scores PSNR (the truth's
range as the peak).

  python3 scripts/representation_marker_resampling.py

Needs NumPy and SciPy. Deterministic.
"""
import sys

try:
    import numpy as np
    from scipy.ndimage import map_coordinates
except ImportError as e:  # pragma: no cover
    sys.exit(f"representation_marker_resampling.py: needs NumPy and SciPy ({e})")

ROWS, COLS, FACTOR = 320, 428, 4          # sensor pixels (cols rounded to a multiple of 4)
PITCH, RADIUS, DARKNESS, GREY = 1.2 / 0.07, 0.22 / 0.07, 0.7, 0.53
BUMP = 40.0                                # displacement field's width, sensor pixels


def markers(r, c):
    """The printed pattern at sensor-pixel positions (r, c): 1 - darkness * coverage."""
    dr, dc = (r - ROWS / 2) / PITCH, (c - COLS / 2) / PITCH
    d = np.hypot((dr - np.round(dr)) * PITCH, (dc - np.round(dc)) * PITCH)
    return 1 - DARKNESS * np.clip(RADIUS + 0.5 - d, 0, 1)


def area(image):
    return image.reshape(ROWS // FACTOR, FACTOR, COLS // FACTOR, FACTOR).mean((1, 3))


def main():
    rr, cc = np.mgrid[0:ROWS, 0:COLS].astype(np.float64) + 0.5
    reference = area(GREY * markers(rr, cc))
    bump = np.exp(-((rr - ROWS / 2) ** 2 + (cc - COLS / 2) ** 2) / (2 * BUMP ** 2))
    r, c = np.mgrid[0:ROWS // FACTOR, 0:COLS // FACTOR].astype(np.float64)
    print("largest shift (working px) | bilinear on the resized reference | bicubic on it")
    for shift in (0.25, 0.5, 1.0, 1.5):
        amp = shift * FACTOR / (np.exp(-0.5))          # radial field peaks at r = BUMP
        d_r = amp * bump * (rr - ROWS / 2) / BUMP
        d_c = amp * bump * (cc - COLS / 2) / BUMP
        truth = area(GREY * markers(rr - d_r, cc - d_c)) - reference
        peak = truth.max() - truth.min()
        row = []
        for order in (1, 3):
            moved = map_coordinates(reference, [r - area(d_r) / FACTOR, c - area(d_c) / FACTOR],
                                    order=order, mode="nearest") - reference
            row.append(10 * np.log10(peak ** 2 / np.mean((moved - truth) ** 2)))
        print(f"{shift:.2f} | {row[0]:.1f} dB | {row[1]:.1f} dB")


if __name__ == "__main__":
    main()
