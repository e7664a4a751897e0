#!/bin/bash
# MPI scaling of multi-brick models (docs/MPI.md, numbers in docs/benchmarks.md "MPI scaling").
#   bench/mpi_scaling.sh BUILD_DIR WORK_DIR [STEPS]
# Weak scaling: one 128^3 brick per rank (volume 128 x 128 x 128N), N = 1, 2 and 4 (4 oversubscribes a
# 2-core machine: marked so). Strong scaling: a generated 512^3 float32 volume (Marschner-Lobb) in
# 2x2x2 bricks on 1, 2 and 4 ranks. Each run: train (STEPS per brick, config small, 1 thread per rank),
# decode and eval; wall time of each command, the busiest rank's CPU seconds (user + sys: what the wall
# time would be with a free core per rank, so a shared, loaded machine still shows the scaling) and the
# largest per-rank peak RSS (/usr/bin/time).
# Writes WORK_DIR/mpi_scaling.tsv. Needs ~1.5 GiB of disk in WORK_DIR for the 512^3 volume.
set -eu
BUILD=$(cd "$1" && pwd)
WORK=$2
STEPS=${3:-200}
V=$BUILD/vnr
mkdir -p "$WORK" && cd "$WORK"
CORES=$(nproc --all)  # before OMP_NUM_THREADS, which GNU nproc honours
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMP_NUM_THREADS=1
OUT=mpi_scaling.tsv
echo -e "kind\tranks\toversubscribed\tdims\tbricks\ttrain_s\ttrain_cpu_s\tdecode_s\tdecode_cpu_s\teval_s\teval_cpu_s\tpsnr\tpeak_rss_mib\tbrick_train_s" > $OUT

# Runs `vnr ARGS` on N ranks; prints "WALL_S BUSIEST_RANK_CPU_S"; appends the ranks' peak RSS (KiB) to rss.txt.
timed() {
  local n=$1
  shift
  rm -f cpu.txt
  local t0=$(date +%s.%N)
  mpirun -n "$n" --oversubscribe --bind-to none /usr/bin/time -a -o cpu.txt -f "%M %U %S" "$V" "$@" > /dev/null 2>> log.txt
  local wall=$(echo "$(date +%s.%N) - $t0" | bc)
  awk '{print $1}' cpu.txt >> rss.txt
  printf "%.2f\t%.2f" "$wall" "$(awk '{c = $2 + $3; if (c > m) m = c} END {print m}' cpu.txt)"
}

case_run() {  # kind N volume.json grid dims
  local kind=$1 n=$2 vol=$3 grid=$4 dims=$5
  rm -rf model out.raw out.json rss.txt
  local tt=$(timed "$n" train "$vol" -o model --bricks "$grid" --ghost 4 --steps "$STEPS" --config small --threads 1 -q --device cpu)
  local td=$(timed "$n" decode model -o out.raw --precision fp32 --threads 1)
  local te=$(timed "$n" eval model "$vol" --precision fp32 --threads 1 --report eval.json)
  local psnr=$(/usr/bin/python3 -c "import json; print('%.2f' % json.load(open('eval.json'))['psnr'])")
  local rss=$(sort -n rss.txt | tail -1)
  # Mean training seconds of one brick (its session alone, from the manifest).
  local brick=$(/usr/bin/python3 -c "import json; b=json.load(open('model/manifest.json'))['bricks']; print('%.2f' % (sum(x['training']['seconds'] for x in b) / len(b)))")
  local over=no
  [ "$n" -gt "$CORES" ] && over=yes
  echo -e "$kind\t$n\t$over\t$dims\t$grid\t$tt\t$td\t$te\t$psnr\t$((rss / 1024))\t$brick" | tee -a $OUT
}

for n in 1 2 4; do
  z=$((128 * n))
  [ -f weak$n.json ] || "$V" synth marschner-lobb --dims 128,128,$z -o weak$n.json > /dev/null
  case_run weak $n weak$n.json 1,1,$n 128x128x$z
done
[ -f strong.json ] || "$V" synth marschner-lobb --dims 512,512,512 -o strong.json > /dev/null
for n in 1 2 4; do
  case_run strong $n strong.json 2,2,2 512x512x512
done
rm -f out.raw
