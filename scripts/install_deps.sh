#!/usr/bin/env bash
# Installs the Debian 12 packages tactfunc builds against, if any is missing.
# Idempotent: with everything present it only checks and returns (about a second).
set -euo pipefail
PACKAGES=(
  g++ cmake make pkg-config
  libeigen3-dev libceres-dev libflann-dev liblz4-dev
  libopencv-dev libboost-dev libpng-dev zlib1g-dev libdeflate-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  libcli11-dev nlohmann-json3-dev
  libopenmpi-dev openmpi-bin
)
missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install_deps: all ${#PACKAGES[@]} packages present"
  exit 0
fi
echo "install_deps: installing ${missing[*]}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
# --no-install-recommends keeps the download to ~170 MB (the recommends are GUI/VA stacks).
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "install_deps: done"
