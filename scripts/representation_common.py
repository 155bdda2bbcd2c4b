"""What the representation study scripts share: tactfunc's PSNR on exported targets and
a picture sheet of frames, and the moments of a frame's difference energy."""
import math
import os

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


def energy_moments(frames, xy, weights=None):
    """Per frame (N, h, w, C) of the difference's energy e_j = w_j sum_c f_jc^2 over the
    pixels at xy (h w x 2, row-major; weights N x h x w or None = all 1): the centroid t
    (N x 2), the principal axis's angle theta = atan2(2 c01, c00 - c11) / 2 of the second
    central moments c, the third moment along that axis (its sign tells which way the
    energy is skewed) and the spread sqrt(c00 + c11); zeros for a frame without energy."""
    n = len(frames)
    t, theta = np.zeros((n, 2)), np.zeros(n)
    skew, spread = np.zeros(n), np.zeros(n)
    for i in range(n):
        e = (frames[i].reshape(len(xy), -1).astype(np.float64) ** 2).sum(1)
        if weights is not None:
            e = e * weights[i].reshape(-1)
        total = e.sum()
        if not total > 0:
            continue
        t[i] = (e[:, None] * xy).sum(0) / total
        d = xy - t[i]
        cov = (e[:, None, None] * d[:, :, None] * d[:, None, :]).sum(0) / total
        theta[i] = 0.5 * math.atan2(2 * cov[0, 1], cov[0, 0] - cov[1, 1])
        axis = np.array([math.cos(theta[i]), math.sin(theta[i])])
        skew[i] = (e * (d @ axis) ** 3).sum()
        spread[i] = math.sqrt(max(cov[0, 0] + cov[1, 1], 1e-12))
    return t, theta, skew, spread


def write_png(path, image):
    """An 8-bit grayscale PNG (zlib only), atomically."""
    import struct
    import zlib
    image = np.clip(np.rint(image), 0, 255).astype(np.uint8)
    h, w = image.shape
    raw = b"".join(b"\x00" + image[r].tobytes() for r in range(h))

    def chunk(kind, data):
        return (struct.pack(">I", len(data)) + kind + data +
                struct.pack(">I", zlib.crc32(kind + data) & 0xffffffff))

    data = (b"\x89PNG\r\n\x1a\n" +
            chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)) +
            chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))
    with open(path + ".tmp", "wb") as f:
        f.write(data)
    os.replace(path + ".tmp", path)


def write_sheet(path, rows, count, zoom=2):
    """Rows of frames (N, h, w, C; channel 0), each frame scaled by the range of the first
    row's frame, enlarged `zoom` times."""
    reference = rows[0]
    tiles = []
    for row in rows:
        cells = []
        for i in range(min(count, len(reference))):
            lo, hi = float(reference[i].min()), float(reference[i].max())
            cell = (row[i][..., 0] - lo) / max(hi - lo, 1e-9) * 255
            cells.append(np.kron(cell, np.ones((zoom, zoom))))
        tiles.append(np.concatenate(cells, 1))
    write_png(path, np.concatenate(tiles, 0))
