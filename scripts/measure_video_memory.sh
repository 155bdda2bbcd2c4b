#!/usr/bin/env bash
# Peak resident memory of reading long videos (docs/DATASET_FORMAT.md, "Memory"): writes
# MJPG .avi videos of 640x480 synthetic GelSight-like frames, 225 and 2000 frames long,
# and measures `tactfunc info`, `encode` and `recon` over each as child processes
# (`tactfunc bench video-memory`, apps/bench_video_memory.cc), next to the program's
# baseline (`tactfunc --version`: its shared libraries).
# With a second tactfunc program (e.g. a build of an older commit) also measures that
# one on the 225-frame video, for comparison. Needs build/bin/tactfunc.
#   scripts/measure_video_memory.sh [WORK_DIR] [OTHER_TACTFUNC]
#   (WORK_DIR default: a fresh temporary folder; its videos are reused if present)
set -euo pipefail
cd "$(dirname "$0")/.."
tactfunc=$PWD/build/bin/tactfunc
work=${1:-$(mktemp -d)}
other=${2:-}
"$tactfunc" bench video-memory --frames 225,2000 --work "$work"
if [[ -n "$other" ]]; then
  "$tactfunc" bench video-memory --frames 225 --work "$work" --tactfunc "$other"
fi
