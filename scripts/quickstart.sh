#!/usr/bin/env bash
# README command 1: install what is missing, build, and run the demo on small data.
# Idempotent; rerunning rebuilds incrementally and regenerates demo/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
bash scripts/build.sh
bash scripts/demo.sh
