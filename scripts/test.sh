#!/bin/sh
# Installs dependencies, builds vnr and runs the whole test suite (what CI runs), then the suite again
# under AddressSanitizer + UBSan and the threaded tests under ThreadSanitizer (scripts/sanitize.sh;
# VNR_SKIP_SANITIZE=1 skips both sanitizer passes).
set -eu
cd "$(dirname "$0")/.."
sh scripts/setup.sh
sh scripts/build.sh
ctest --test-dir build --output-on-failure -j "$(nproc)"
[ -n "${VNR_SKIP_SANITIZE:-}" ] || sh scripts/sanitize.sh address
[ -n "${VNR_SKIP_SANITIZE:-}" ] || sh scripts/sanitize.sh thread
