#!/bin/sh
# Installs every Debian 12 package that building, testing and running the vnr demo needs. The viewer
# (`vnr view`) serves with Boost.Beast and encodes frames with libturbojpeg; its browser tests drive
# Debian's Chromium through Selenium. The Python module builds with pybind11 for Debian's python3
# (numpy, pytest); HDF5 and NetCDF volumes read through libhdf5 and libnetcdf (h5py and netCDF4 write
# the tests' files); the ParaView plugin runs in Debian's ParaView (pvpython, under Xvfb in tests).
# clang builds the libFuzzer targets (scripts/fuzz.sh; libFuzzer and the sanitizer runtimes are in
# libclang-rt-dev, clang's OpenMP in libomp-dev) and the ThreadSanitizer build (scripts/sanitize.sh thread:
# LLVM's libomp and its Archer tool, in libomp-dev).
set -eu
PKGS="build-essential cmake ninja-build ccache pkg-config git \
  nlohmann-json3-dev libcli11-dev libfmt-dev libpng-dev zlib1g-dev libhwy-dev libzstd-dev \
  libgtest-dev libgmock-dev libbenchmark-dev \
  libboost-dev libturbojpeg0-dev libzfp-dev chromium chromium-driver python3-selenium \
  pybind11-dev python3-dev python3-numpy python3-pytest libhdf5-dev libnetcdf-dev python3-h5py \
  python3-netcdf4 python3-matplotlib paraview python3-paraview xvfb xauth libopenmpi-dev openmpi-bin \
  clang libclang-rt-dev libomp-dev"
missing=""
for p in $PKGS; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
if [ -n "$missing" ]; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq $missing
fi
