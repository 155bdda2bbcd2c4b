#!/usr/bin/env python3
"""Turns Taxim's GelSight ball-press pack into a tactfunc user folder.

Usage: scripts/import_taxim_ballpress.py dataPack_small.npz LICENSE OUT_DIR

The pack (Robo-Touch/Taxim, calibs/dataPack_small.npz, MIT licence) holds a GelSight's
no-contact frame `f0` (120 x 160, BGR), 49 ball presses `imgs`, their hand-placed contact
centres `touch_center` (x = column, y = row, pixels) and radii `touch_radius`, and the
original file names `names`. This writes, with the standard library only:

  OUT_DIR/reference.png       the no-contact frame, 8-bit RGB
  OUT_DIR/press_NN.png        the presses in the pack's order (NN = 01 .. 49), 8-bit RGB
  OUT_DIR/contacts.csv        frame,x_px,y_px,radius_px,source_name
  OUT_DIR/LICENSE             the pack's licence, copied unchanged

tests/data/taxim_ballpress/ was made by this script; the real-sensor tests read it as a
user's own folder (tactfunc infers the optical sensor kind from the 8-bit reference).
"""
import ast
import shutil
import struct
import sys
import zipfile
import zlib
from pathlib import Path


def read_npy(blob):
    """(header dict, raw data bytes) of one .npy file (format 1.0 or 2.0)."""
    if blob[:6] != b"\x93NUMPY":
        raise ValueError("not a .npy file")
    major = blob[6]
    if major == 1:
        (header_len,) = struct.unpack("<H", blob[8:10])
        start = 10
    else:
        (header_len,) = struct.unpack("<I", blob[8:12])
        start = 12
    header = ast.literal_eval(blob[start:start + header_len].decode("latin1"))
    if header["fortran_order"]:
        raise ValueError("Fortran-ordered arrays are not supported")
    return header, blob[start + header_len:]


def write_png_rgb(path, rows, cols, rgb):
    """An 8-bit RGB PNG from row-major R, G, B bytes (filter 0 on every row)."""
    raw = b"".join(b"\x00" + rgb[r * cols * 3:(r + 1) * cols * 3] for r in range(rows))

    def chunk(kind, data):
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    png = (b"\x89PNG\r\n\x1a\n" +
           chunk(b"IHDR", struct.pack(">IIBBBBB", cols, rows, 8, 2, 0, 0, 0)) +
           chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))
    tmp = path.with_name("." + path.name + ".tmp")
    tmp.write_bytes(png)
    tmp.replace(path)


def bgr_to_rgb(bgr):
    out = bytearray(bgr)
    out[0::3], out[2::3] = bgr[2::3], bgr[0::3]
    return bytes(out)


def main(argv):
    if len(argv) != 4:
        sys.exit(__doc__)
    pack, licence, out = Path(argv[1]), Path(argv[2]), Path(argv[3])
    arrays = {}
    with zipfile.ZipFile(pack) as z:
        for name in ("f0", "imgs", "touch_center", "touch_radius", "names"):
            arrays[name] = read_npy(z.read(name + ".npy"))
    (h0, ref) = arrays["f0"]
    rows, cols, channels = h0["shape"]
    if channels != 3 or h0["descr"] != "|u1":
        sys.exit(f"{pack}: f0: expected (rows, cols, 3) uint8, got {h0}")
    (hi, imgs) = arrays["imgs"]
    count = hi["shape"][0]
    if tuple(hi["shape"][1:]) != (rows, cols, 3) or hi["descr"] != "|u1":
        sys.exit(f"{pack}: imgs: expected ({count}, {rows}, {cols}, 3) uint8, got {hi}")
    centres = struct.unpack(f"<{2 * count}d", arrays["touch_center"][1][:16 * count])
    radii = struct.unpack(f"<{count}q", arrays["touch_radius"][1][:8 * count])
    (hn, names_raw) = arrays["names"]
    width = int(hn["descr"][2:])  # '<U12': UTF-32 code units per name
    names = [names_raw[i * 4 * width:(i + 1) * 4 * width].decode("utf-32-le").rstrip("\x00")
             for i in range(count)]

    out.mkdir(parents=True, exist_ok=True)
    frame_bytes = rows * cols * 3
    write_png_rgb(out / "reference.png", rows, cols, bgr_to_rgb(ref[:frame_bytes]))
    lines = ["frame,x_px,y_px,radius_px,source_name"]
    for i in range(count):
        frame = f"press_{i + 1:02d}"
        pixels = imgs[i * frame_bytes:(i + 1) * frame_bytes]
        write_png_rgb(out / f"{frame}.png", rows, cols, bgr_to_rgb(pixels))
        lines.append(f"{frame},{centres[2 * i]:g},{centres[2 * i + 1]:g},{radii[i]},{names[i]}")
    tmp = out / ".contacts.csv.tmp"
    tmp.write_text("\n".join(lines) + "\n")
    tmp.replace(out / "contacts.csv")
    shutil.copyfile(licence, out / "LICENSE")
    print(f"{out}: reference and {count} presses of {rows} x {cols}, contacts.csv, LICENSE")


if __name__ == "__main__":
    main(sys.argv)
