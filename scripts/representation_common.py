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


def read_png(path):
    """An 8-bit PNG (grayscale, RGB or RGBA, not interlaced) as a (h, w, channels) uint8
    array, with zlib and NumPy only."""
    import struct
    import zlib
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"{path}: not a PNG file")
    pos, idat, header = 8, [], None
    while pos < len(data):
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + length]
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat.append(body)
        pos += 12 + length
    w, h, depth, color, _, _, interlace = header
    channels = {0: 1, 2: 3, 6: 4}.get(color)
    if depth != 8 or channels is None or interlace != 0:
        raise ValueError(f"{path}: only 8-bit grayscale/RGB/RGBA non-interlaced PNGs are read "
                         f"(bit depth {depth}, colour type {color}, interlace {interlace})")
    raw = np.frombuffer(zlib.decompress(b"".join(idat)), np.uint8)
    stride = w * channels
    rows = raw.reshape(h, stride + 1)
    out = np.zeros((h, stride), np.int32)
    prev = np.zeros(stride, np.int32)
    for r in range(h):
        kind, line = rows[r, 0], rows[r, 1:].astype(np.int32)
        if kind == 0:
            cur = line
        elif kind == 2:
            cur = (line + prev) & 255
        else:  # Sub, Average and Paeth depend on the pixel to the left: pixel by pixel
            cur = np.zeros(stride, np.int32)
            for i in range(stride):
                left = cur[i - channels] if i >= channels else 0
                up = prev[i]
                if kind == 1:
                    cur[i] = (line[i] + left) & 255
                elif kind == 3:
                    cur[i] = (line[i] + (left + up) // 2) & 255
                else:
                    up_left = prev[i - channels] if i >= channels else 0
                    p = left + up - up_left
                    pa, pb, pc = abs(p - left), abs(p - up), abs(p - up_left)
                    pred = left if pa <= pb and pa <= pc else (up if pb <= pc else up_left)
                    cur[i] = (line[i] + pred) & 255
        out[r] = cur
        prev = cur
    return out.reshape(h, w, channels).astype(np.uint8)
