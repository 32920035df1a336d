#!/usr/bin/env bash
# Installs every Debian package DMPlatform, its tests, its benchmarks' peer
# libraries and its data need. Idempotent: quiet and quick when all are present.
# Usage: scripts/setup.sh            (as root, or with sudo available)
set -euo pipefail

packages=(
  # toolchain
  build-essential cmake ninja-build ccache pkg-config git clang clang-format clang-tidy
  libclang-rt-14-dev
  # libraries the SDK links
  libeigen3-dev libode-dev libopencv-dev libopencv-contrib-dev libopenvdb-dev
  libboost-iostreams-dev libsundials-dev libassimp-dev libegl-dev libegl1-mesa-dev
  libgl1-mesa-dri libgbm-dev libtbb-dev libspdlog-dev libfmt-dev nlohmann-json3-dev
  libcli11-dev libasio-dev libssl-dev libdcmtk-dev libpng-dev zlib1g-dev libfreetype-dev fonts-dejavu-core
  # the editor (dmedit: Dear ImGui on GLFW; its test runs it under Xvfb)
  libglfw3-dev libimgui-dev libstb-dev xvfb
  # the Python package (Debian's /usr/bin/python3), its sweeps on Dask and its tests
  pybind11-dev python3-dev python3-numpy python3-distributed python3-pytest
  # tests and benchmarks
  libgtest-dev libgmock-dev libbenchmark-dev
  # peer libraries (benchmarks and interoperability tests only)
  libfcl-dev liboctomap-dev libbullet-dev libccd-dev libvtk9-dev libopenigtlink-dev libnanoflann-dev
  # real data (see shared/DATA.md)
  mricron-data assimp-testmodels opencv-doc opencv-data dcmtk
)

missing=()
for p in "${packages[@]}"; do
  # dpkg-query prints "install ok installed" only for a fully installed package.
  if [ "$(dpkg-query -W -f='${Status}' "$p" 2>/dev/null)" != "install ok installed" ]; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "setup: need root or sudo to install: ${missing[*]}" >&2; exit 1; }
  SUDO=sudo
fi
echo "setup: installing ${#missing[@]} Debian packages: ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "setup: done"
