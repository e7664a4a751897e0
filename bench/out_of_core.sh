#!/bin/sh
# Out-of-core sampling against the memory-mapped baseline (paper, "Out-of-Core Sampling").
# Generates a volume larger than this machine's memory (unless it exists), then trains the same
# model the same number of steps with `--sampler outofcore` and `--sampler mmap`, each after
# dropping the page cache (when this user may), and prints seconds per step and the sampled PSNR.
#
#   sh bench/out_of_core.sh DATA_DIR [STEPS] [DIMS] [BUDGET]
#   defaults: STEPS 10, DIMS 2048,2048,1600 (25.6 GB of float32), BUDGET 256MiB
# Needs about 26 GB free in DATA_DIR. Results: DATA_DIR/ooc_{outofcore,mmap}.json and a table.
# SAMPLERS="outofcore" reruns one sampler only (mmap takes minutes per step); the table then
# uses the other sampler's report from an earlier run in DATA_DIR and says so.
set -eu
DIR=${1:?usage: sh bench/out_of_core.sh DATA_DIR [STEPS] [DIMS] [BUDGET]}
STEPS=${2:-10}
DIMS=${3:-2048,2048,1600}
BUDGET=${4:-256MiB}
VNR=${VNR:-$(dirname "$0")/../build/vnr}
mkdir -p "$DIR"
VOL="$DIR/big.json"
if [ ! -f "$VOL" ] || [ ! -f "$DIR/big.raw" ]; then
  echo "generating $DIMS float32 noise volume in $DIR ..."
  "$VNR" synth noise --dims "$DIMS" -o "$VOL" --force
fi
drop_caches() {
  sync
  if (echo 3 > /proc/sys/vm/drop_caches) 2>/dev/null; then echo "page cache dropped"; else
    echo "note: cannot drop the page cache (not root); the first run may find data cached"; fi
}
for S in ${SAMPLERS:-outofcore mmap}; do
  drop_caches
  echo "== $S: $STEPS steps, paper config"
  "$VNR" train "$VOL" -o "$DIR/ooc_$S.vnr" --config paper --steps "$STEPS" --sampler "$S" \
    --memory-budget "$BUDGET" --eval-samples 65536 --no-ssim --report "$DIR/ooc_$S.json"
done
python3 - "$DIR" "${SAMPLERS:-outofcore mmap}" <<'PY'
import json, os, sys, time
d, ran = sys.argv[1], sys.argv[2].split()
r = {s: json.load(open(f"{d}/ooc_{s}.json")) for s in ("outofcore", "mmap")}
for s in r:
    if s not in ran:
        t = time.strftime("%Y-%m-%d %H:%M", time.localtime(os.path.getmtime(f"{d}/ooc_{s}.json")))
        print(f"note: {s} was not run now; its row is the earlier report from {t}")
print("| sampler | steps | median s/step | mean s/step | buffer fill s | PSNR (65,536 voxels, 95% CI) |")
print("|---|---|---|---|---|---|")
for s, j in r.items():
    ci = j["evaluation"].get("psnr_ci95", [0, 0])
    fill = j.get("out_of_core", {}).get("fill_seconds", 0)
    print(f"| {s} | {j['steps']} | {j['median_step_seconds']:.3f} | {j['seconds_per_step']:.3f} | {fill:.1f} | "
          f"{j['psnr']:.2f} ({ci[0]:.2f}..{ci[1]:.2f}) |")
print(f"\noutofcore is {r['mmap']['median_step_seconds'] / r['outofcore']['median_step_seconds']:.1f}x faster per step "
      f"(median), {r['mmap']['seconds_per_step'] / r['outofcore']['seconds_per_step']:.1f}x (mean)")
PY
