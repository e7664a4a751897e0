#!/bin/sh
# Prepares what a GPU machine that reaches no package registry and has no copy of the project's shared
# folder (SHARED, default ../shared: its data set and the PyTorch reference trainer) needs from here, in
# folders of the repo that git ignores (listed in .git/info/exclude) so the device tool can carry them:
#   .debs   the Debian build dependencies (scripts/gpu_debs.sh)
#   .data   the real volumes of the rendering table (bonsai, engine, chris_t1; ~33 MB)
#   .peers  the peer programs (the PyTorch trainer)
# Then, on the GPU machine: sh bench/gpu.sh OUT (it finds .debs, .data and .peers by itself).
set -eu
cd "$(dirname "$0")/.."
SHARED=${1:-../shared}
mkdir -p "$(git rev-parse --git-path info)"
for d in .debs .data .peers; do
  ex=$(git rev-parse --git-path info/exclude)
  grep -qx "/$d/" "$ex" 2>/dev/null || echo "/$d/" >> "$ex"
done
[ -d .debs ] || sh scripts/gpu_debs.sh .debs > /dev/null
mkdir -p .data .peers
for name in bonsai engine chris_t1; do
  if [ -f "$SHARED/data/$name.json" ]; then
    cp "$SHARED/data/$name.json" .data/
    cp "$SHARED/data/$name"_*.raw .data/
  fi
done
[ -f "$SHARED/peers/torch_vnr.py" ] && cp "$SHARED/peers/torch_vnr.py" .peers/
du -sh .debs .data .peers
