#!/bin/bash
# In-core against out-of-core bricks (docs/MPI.md, docs/benchmarks.md "Out-of-core bricks"): the same
# multi-brick model of VOLUME trained with every brick in memory, with every brick out of core under a
# budget smaller than a brick (the buffer then holds a fraction of it), and out of core with every block
# resident (--sampler outofcore, the default budget). Prints PSNR over the whole volume, the wall time of
# the command (reading, training, the bricks' own evaluations, the final whole-volume evaluation) and the
# bricks' training seconds (the sum of training.seconds in the manifest).
# Usage: bench/bricks_outofcore.sh VOLUME [STEPS] [BUDGET]   (VNR: the vnr binary, default build/vnr)
set -eu
VOL=${1:?volume}
STEPS=${2:-300}
BUDGET=${3:-4MiB}
V=${VNR:-build/vnr}
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
COMMON=(--bricks 2,2,2 --ghost 4 --config small --steps "$STEPS" --no-ssim)
run() {  # name, extra options
  local name=$1
  shift
  local t0=$(date +%s.%N)
  "$V" train "$VOL" -o "$OUT/$name" "${COMMON[@]}" "$@" -q --report "$OUT/$name.json" > /dev/null
  local t1=$(date +%s.%N)
  /usr/bin/python3 -c "
import json, sys
r = json.load(open(sys.argv[1])); m = json.load(open(sys.argv[2]))
train = sum(b['training']['seconds'] for b in m['bricks'])
print(f'{sys.argv[3]:<44} PSNR {r[\"psnr\"]:.2f} dB  wall {float(sys.argv[4]):.1f} s  training {train:.1f} s')" \
    "$OUT/$name.json" "$OUT/$name/manifest.json" "$name $*" "$(echo "$t1 - $t0" | bc)"
}
run incore
run outofcore --memory-budget "$BUDGET"
run outofcore_all_resident --sampler outofcore
