#!/usr/bin/env bash
# Configures and builds tactfunc into ./build (Release, -O3, -march=native by default).
# Extra arguments go to the configure step, e.g. -DTACTFUNC_NATIVE=OFF.
set -euo pipefail
cd "$(dirname "$0")/.."
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release "$@" >build.configure.log 2>&1 ||
  { cat build.configure.log; exit 1; }
# Progress lines are filtered out; the build's own exit status decides (set -o pipefail above).
cmake --build build -j"$(nproc)" 2>&1 | { grep -Ev '^\[ *[0-9]+%\]|^-- ' || true; }
test -x build/bin/tactfunc
echo "build: ok (build/bin/tactfunc)"
