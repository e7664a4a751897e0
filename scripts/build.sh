#!/bin/sh
# Configures and builds vnr in ./build (Release, Ninja, ccache when present).
set -eu
cd "$(dirname "$0")/.."
LAUNCHER=""
command -v ccache >/dev/null 2>&1 && LAUNCHER="-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_CUDA_COMPILER_LAUNCHER=ccache"
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release $LAUNCHER "$@" >/dev/null
cmake --build build -j "$(nproc)"
