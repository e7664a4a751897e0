#!/bin/sh
# Downloads (does not install) the Debian 12 packages that building vnr needs beyond a CUDA image's
# compiler and CMake, into DIR (default .debs), for a GPU machine that reaches no package registry:
# carry DIR there and bench/gpu.sh unpacks them under /tmp/vnr-deps. Run where apt works.
set -eu
DIR=${1:-.debs}
mkdir -p "$DIR"
cd "$DIR"
apt-get download nlohmann-json3-dev libcli11-dev libfmt-dev libfmt9 libpng-dev libpng16-16 zlib1g-dev \
  libhwy-dev libhwy1 libgtest-dev libgmock-dev
ls -l
