#!/usr/bin/env bash
# Peak memory of refusing an oversized frame (docs/RELIABILITY.md): writes a real
# 20000 x 20000 16-bit PNG (800 MB of pixels, streamed through zlib: a few MB on disk)
# and measures, with /usr/bin/time -v, the peak resident memory of
#   1. tactfunc fit --frame BIG.png   (a frame given on the command line), and
#   2. tactfunc show DIR              (a dataset whose frame 000000 was replaced by it),
# both of which must refuse the frame from its header, and for comparison
#   0. tactfunc --version             (the program's baseline: its shared libraries).
# Needs build/bin/tactfunc.
#   scripts/measure_oversized_frame.sh [WORK_DIR]   (default: a fresh temporary folder)
set -euo pipefail
cd "$(dirname "$0")/.."
tactfunc=$PWD/build/bin/tactfunc
work=${1:-$(mktemp -d)}
mkdir -p "$work"
python3 - "$work/big.png" <<'PY'
import struct, sys, zlib
width = height = 20000
def chunk(kind, data):
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
with open(sys.argv[1], "wb") as out:
    out.write(b"\x89PNG\r\n\x1a\n")
    out.write(chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 16, 0, 0, 0, 0)))
    z = zlib.compressobj(9)
    row = b"\x00" + b"\x75\x30" * width  # filter byte, then 30000 um per pixel
    data = b"".join(z.compress(row) for _ in range(height)) + z.flush()
    out.write(chunk(b"IDAT", data))
    out.write(chunk(b"IEND", b""))
PY
echo "wrote $work/big.png: $(stat -c %s "$work/big.png") bytes, 20000x20000 16-bit"
rm -rf "$work/d"
"$tactfunc" synth --out "$work/d" --frames-per-tool 1 --tools rod --sensors bubble --seed 1 >/dev/null 2>&1
cp "$work/big.png" "$work/d/bubble/000000.png"
measure() {
  local label=$1; shift
  /usr/bin/time -v "$@" >"$work/out.txt" 2>"$work/err.txt" && status=0 || status=$?
  echo "$label: exit $status, peak RSS $(grep 'Maximum resident set size' "$work/err.txt" | grep -o '[0-9]*') kB"
  grep 'error:' "$work/err.txt" | head -1 || true
}
measure "--version (baseline)" "$tactfunc" --version
measure "fit --frame big.png" "$tactfunc" fit --model models/pretrained/default.tfm \
  --frame "$work/big.png" --reference "$work/d/bubble/reference.png" --sensor bubble
measure "show (dataset frame big.png)" "$tactfunc" show "$work/d" --out "$work/sheet.png"
