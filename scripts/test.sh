#!/bin/sh
# Installs dependencies, builds vnr and runs the whole test suite (what CI runs), then the suite again
# under AddressSanitizer + UBSan and the threaded tests under ThreadSanitizer (scripts/sanitize.sh;
# VNR_SKIP_SANITIZE=1 skips both sanitizer passes).
set -eu
cd "$(dirname "$0")/.."
sh scripts/setup.sh
# Without a GPU (CI) the CUDA code is only compiled: for compute_75 PTX (the code paths below Hopper) and
# sm_90 (the Hopper ones), not for every architecture a release build carries (docs/benchmarks.md,
# "Build time"). With a GPU, CMake's default list, and the GPU tests run.
if nvidia-smi -L >/dev/null 2>&1; then
  sh scripts/build.sh
else
  sh scripts/build.sh "-DCMAKE_CUDA_ARCHITECTURES=75-virtual;90-real"
fi
ctest --test-dir build --output-on-failure -j "$(nproc)"
[ -n "${VNR_SKIP_SANITIZE:-}" ] || sh scripts/sanitize.sh address
[ -n "${VNR_SKIP_SANITIZE:-}" ] || sh scripts/sanitize.sh thread
