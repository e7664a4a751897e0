#!/bin/sh
# Installs dependencies, builds vnr and runs the whole test suite (what CI runs).
set -eu
cd "$(dirname "$0")/.."
sh scripts/setup.sh
sh scripts/build.sh
ctest --test-dir build --output-on-failure -j "$(nproc)"
