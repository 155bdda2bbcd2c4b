#!/usr/bin/env python3
"""How far general-purpose entropy coders shrink a functaset's stored latents: does an
entropy-coded latent store pay for a coder in the file format?

For every sensor of each functaset (.tfs, read as docs/FUNCTASET.md's reader does), the
latents as float16 and as 8-bit codes on the functaset's per-dimension grid are
compressed whole (every frame in one stream: the best case for a coder, which a file
that reads frames one by one would not reach) with zlib (level 9), LZMA (preset 9e) and
bzip2 (level 9), float16 also after splitting the high and low bytes into two planes
(the byte shuffle of Blosc). The per-dimension empirical entropy of the 8-bit codes is
the bound of a static coder with one histogram per latent dimension (a model the file
would also have to store). Printed as bytes and as a fraction of the raw bytes.

  python3 scripts/latent_compressibility.py SET.tfs [MORE.tfs ...]

Needs NumPy. Deterministic.
"""
import bz2
import json
import lzma
import struct
import sys
import zlib

try:
    import numpy as np
except ImportError as e:  # pragma: no cover
    sys.exit(f"latent_compressibility.py: needs NumPy ({e})")


def read_latents(path):
    """{sensor: float32 latents of the entries stored with a latent row}."""
    with open(path, "rb") as f:
        b = f.read()
    if b[:8] != b"TACTFUNC":
        sys.exit(f"latent_compressibility.py: {path} is not a tactfunc file")
    (n,) = struct.unpack("<Q", b[16:24])
    head = json.loads(b[24:24 + n])
    p = 24 + n
    if head.get("kind") != "functaset":
        sys.exit(f"latent_compressibility.py: {path} is a '{head.get('kind')}' file, "
                 "expected a functaset")
    t = {d["name"]: np.frombuffer(b, d["dtype"], int(np.prod(d["shape"])), p + d["offset"])
         .reshape(d["shape"]) for d in head["tensors"]}
    out = {}
    for s in head["meta"]["sensors"]:
        name = s["sensor"] + "/latents"
        if name not in t:
            sys.exit(f"latent_compressibility.py: {path}: sensor {s['sensor']} stores b-bit "
                     "codes; encode it with --latent-precision float16 or float32")
        out[s["sensor"]] = t[name].astype(np.float32)
    return out


def codes_uint8(z):
    """8-bit codes on the functaset's grid (docs/FUNCTASET.md, b-bit codes)."""
    lo, hi = z.min(0), z.max(0)
    step = np.where(hi > lo, (hi - lo) / 255, 1.0)
    return np.clip(np.rint((z - lo) / step), 0, 255).astype(np.uint8)


def main():
    if len(sys.argv) < 2 or sys.argv[1] in ("-h", "--help"):
        print(__doc__)
        sys.exit(0 if len(sys.argv) > 1 else 2)
    print("file | sensor | frames x d | storage | raw bytes | zlib 9 | lzma 9e | bzip2 9 | "
          "shuffled lzma | per-dimension entropy")
    for path in sys.argv[1:]:
        for sensor, z in read_latents(path).items():
            for name, arr in (("float16", z.astype(np.float16)), ("uint8", codes_uint8(z))):
                raw = arr.tobytes()
                cells = [len(zlib.compress(raw, 9)),
                         len(lzma.compress(raw, preset=9 | lzma.PRESET_EXTREME)),
                         len(bz2.compress(raw, 9))]
                if arr.dtype == np.float16:
                    planes = arr.view(np.uint8).reshape(*arr.shape, 2).transpose(2, 0, 1)
                    cells.append(len(lzma.compress(planes.tobytes(),
                                                   preset=9 | lzma.PRESET_EXTREME)))
                    cells.append(None)
                else:
                    bits = 0.0
                    for k in range(arr.shape[1]):
                        p = np.bincount(arr[:, k], minlength=256) / arr.shape[0]
                        p = p[p > 0]
                        bits += float(-(p * np.log2(p)).sum())
                    cells += [None, int(round(bits / 8 * arr.shape[0]))]
                shown = " | ".join("-" if c is None else f"{c} ({c / len(raw):.3f})"
                                   for c in cells)
                print(f"{path} | {sensor} | {arr.shape[0]} x {arr.shape[1]} | {name} | "
                      f"{len(raw)} | {shown}")


if __name__ == "__main__":
    main()
