#!/bin/bash
# ctest mpi_cli_n2 / mpi_cli_n4: `mpirun -n N vnr train|decode|eval` of a multi-brick model against one
# rank and one process. Usage: cli_mpi.sh N SCRATCH_DIR (VNR_CLI names the vnr binary).
# Render: the N-rank sort-last image against 1 rank (bit for bit) and the one-process frame.
# Checks: the model trained on 1 and N ranks and by one process is the same (brick losses, bit-identical
# decodes); the
# N-rank decode is bit-identical to the one-process `vnr decode` (raw and NRRD); the N-rank eval's PSNR
# and SSIM equal the one-process `vnr eval`'s; a rank that fails names itself and its brick while the other
# bricks are kept; a rank killed mid-training leaves its finished bricks and --resume completes the
# model, identical to the uninterrupted one.
set -u
N=$1
DIR=$2
V=${VNR_CLI:?set VNR_CLI to the vnr binary}
PY=/usr/bin/python3
rm -rf "$DIR" && mkdir -p "$DIR" && cd "$DIR" || exit 2
failures=0
check() {  # check "what" command...
  local what=$1
  shift
  if "$@"; then echo "ok: $what"; else echo "FAIL: $what"; failures=$((failures + 1)); fi
}
differ() { ! cmp -s "$1" "$2"; }
run() { mpirun -n "$1" --oversubscribe "${@:2}"; }
COMMON=(--bricks 2,2,2 --ghost 2 --config small --threads 1 -q)

$V synth marschner-lobb --dims 40,36,32 -o vol.json > /dev/null || exit 2
run 1 "$V" train vol.json -o m1 "${COMMON[@]}" --steps 60 > /dev/null || exit 2
run "$N" "$V" train vol.json -o mN "${COMMON[@]}" --steps 60 > /dev/null || exit 2
losses() { $PY -c "import json,sys; print([b['training']['final_loss'] for b in json.load(open(sys.argv[1]))['bricks']])" "$1"; }
check "brick losses on 1 and $N ranks" [ "$(losses m1/manifest.json)" == "$(losses mN/manifest.json)" ]

# Decodes: N ranks (of both models) against one process, bit for bit (fp32 inference: no per-CPU choice).
"$V" decode m1 -o one.raw --precision fp32 -q > /dev/null
"$V" decode m1 -o one.nrrd --precision fp32 --dims 33,20,17 -q > /dev/null
run "$N" "$V" decode m1 -o many.raw --precision fp32 > /dev/null
run "$N" "$V" decode mN -o manyN.raw --precision fp32 > /dev/null
run "$N" "$V" decode m1 -o many.nrrd --precision fp32 --dims 33,20,17 > /dev/null
check "decode on $N ranks = one process" cmp -s one.raw many.raw
check "decode of the $N-rank model = the 1-rank model's" cmp -s one.raw manyN.raw
"$V" train vol.json -o m0 "${COMMON[@]}" --steps 60 > /dev/null
"$V" decode m0 -o zero.raw --precision fp32 -q > /dev/null
check "the $N-rank model = the one-process 'vnr train --bricks' model" cmp -s one.raw zero.raw
check "resampled NRRD decode on $N ranks = one process" cmp -s one.nrrd many.nrrd
check "sidecar as one process writes it" [ "$(sed 's/many.raw/one.raw/' many.json)" == "$(cat one.json)" ]
check "no temporary left" [ -z "$(ls | grep tmp-mpi)" ]

# Eval: the same PSNR, max error and SSIM (sums in another order: 1e-9). 32 slices on N ranks: SSIM windows
# cross every rank boundary.
"$V" eval m1 vol.json --precision fp32 --report e1.json -q > /dev/null
run "$N" "$V" eval m1 vol.json --precision fp32 --report eN.json > /dev/null
run "$N" "$V" eval m1 vol.json --precision fp32 --no-ssim --report eNs.json > /dev/null
check "eval PSNR and SSIM on $N ranks = one process" $PY -c "
import json; a=json.load(open('e1.json')); b=json.load(open('eN.json')); c=json.load(open('eNs.json'))
assert abs(a['psnr']-b['psnr']) < 1e-9 and a['max_abs_error'] == b['max_abs_error'], (a['psnr'], b['psnr'])
assert 0 < a['ssim'] < 1 and abs(a['ssim']-b['ssim']) < 1e-9, (a['ssim'], b['ssim'])
assert c['ssim'] is None and c['psnr'] == b['psnr'], c"

# Render: the N-rank sort-last composite is the 1-rank one bit for bit (same segments, same order, same
# arithmetic), and the one-process frame up to early ray termination: a segment behind a pixel already
# at alpha_stop still adds < 1 - alpha_stop there, and float rounding (the bound below: 40 dB).
VIEW=(--size 64x48 --orbit 30,20 --tf cool-warm --precision fp32 --threads 1)
run 1 "$V" render m1 -o r1.pfm "${VIEW[@]}" -q > /dev/null
run "$N" "$V" render m1 -o rN.pfm "${VIEW[@]}" --report render.json > /dev/null
check "render on $N ranks = on 1 rank, bit for bit" cmp -s r1.pfm rN.pfm
"$V" render m1 -o one.pfm "${VIEW[@]}" --spp 1 --strategy streaming -q --reference rN.pfm --report r.json > /dev/null  # MPI renders one frame
check "render on $N ranks = the one-process frame (image PSNR >= 40 dB), not blank" $PY -c "
import json, numpy as np
p = json.load(open('r.json'))['image_psnr']; print('image PSNR', p); assert p >= 40, p
head, data = open('rN.pfm', 'rb').read().split(b'\n', 3)[1:3], open('rN.pfm', 'rb').read().split(b'\n', 3)[3]
assert np.frombuffer(data, np.float32).std() > 0.05, 'blank image'"
# Ranks draw their bricks on the CPU: --device cuda is refused with one line (auto takes the CPU there).
run "$N" "$V" render m1 -o rc.pfm "${VIEW[@]}" --device cuda -q > cuda.out 2>&1
check "render --device cuda under mpirun: refused, saying why" grep -q "draws each rank's bricks on the CPU" cuda.out

# A rank that fails: brick 1 of 3 along x is the widest with its ghosts (17 voxels) and alone exceeds the budget,
# and its out-of-core buffer (default blocks, 17x31x31) does not fit it either.
run "$N" "$V" train vol.json -o mf --bricks 3,1,1 --ghost 2 --steps 20 --config small --threads 1 -q \
  --memory-budget 76000 > /dev/null 2> fail.txt
status=$?
check "a failing rank fails the job" [ $status -ne 0 ]
check "one error line naming the rank and brick" [ "$(grep -c 'vnr: error: rank [0-9]* of '"$N"' failed training: brick 1 (x 14..27' fail.txt)" == 1 ]
complete() { $PY -c "import json,sys; print((json.load(open(sys.argv[1])).get('training') or {}).get('complete', False))" "$1"; }
check "the other bricks are kept, the model marked incomplete" [ -f mf/brick_00000.vnr -a -f mf/brick_00002.vnr -a "$(complete mf/manifest.json)" == False ]

# A rank killed mid-training: finished bricks stay; --resume trains the rest, giving the same model.
run "$N" "$V" train vol.json -o mk "${COMMON[@]}" --steps 60 > /dev/null 2> kill.txt &
launcher=$!
for _ in $(seq 600); do [ -n "$(ls mk/*.vnr 2> /dev/null)" ] && break; sleep 0.02; done
launcher_pid=$(pgrep -P $launcher -x mpirun)
victim=$(pgrep -P "$launcher_pid" -x vnr | tail -1)  # the last rank mpirun started
[ -n "$victim" ] && kill -9 "$victim"
wait $launcher
status=$?
kept=$(ls mk/*.vnr 2> /dev/null | wc -l)
check "a killed rank fails the job" [ $status -ne 0 ]
check "mpirun names the killed rank" grep -q "exited on signal 9" kill.txt
check "finished bricks kept ($kept of 8), the model incomplete" [ "$kept" -ge 1 -a "$kept" -lt 8 -a "$(complete mk/manifest.json)" == False ]
run "$N" "$V" train vol.json -o mk "${COMMON[@]}" --steps 60 --resume > /dev/null 2> resume.txt
check "--resume completes the model" [ "$(complete mk/manifest.json)" == True ]
"$V" decode mk -o resumed.raw --precision fp32 -q > /dev/null
check "the resumed model = the uninterrupted one" cmp -s resumed.raw manyN.raw

# `vnr train`'s options under mpirun (one setup for both): --precision, --macrocell-size and the out-of-core
# options reach every brick, and bricks over --memory-budget train out of core (saying so), to the model one
# process trains with the same options.
OPTS=(--bricks 2,2,2 --ghost 2 --config small --threads 1 --steps 20 --macrocell-size 0 --memory-budget 30KiB
      --block-dims 4,4,4)
"$V" train vol.json -o o1 "${OPTS[@]}" --precision fp32 -q > /dev/null
run "$N" "$V" train vol.json -o oN "${OPTS[@]}" --precision fp32 > /dev/null 2> ooc.txt
check "bricks over the budget train out of core under mpirun, each saying so" \
  [ "$(grep -c '^rank [0-9]*: note: brick [0-7] trains out of core: its 2.x2.x1. voxels with ghosts need' ooc.txt)" == 8 ]
"$V" decode o1 -o o1.raw --precision fp32 -q > /dev/null
"$V" decode oN -o oN.raw --precision fp32 -q > /dev/null
check "out-of-core bricks on $N ranks = one process" cmp -s o1.raw oN.raw
if "$V" train vol.json -o b1 "${OPTS[@]}" --precision bf16 -q > /dev/null 2>&1; then  # a CPU with AVX512-BF16
  run "$N" "$V" train vol.json -o bN "${OPTS[@]}" --precision bf16 -q > /dev/null
  "$V" decode b1 -o b1.raw --precision fp32 -q > /dev/null
  "$V" decode bN -o bN.raw --precision fp32 -q > /dev/null
  check "--precision bf16 reaches the bricks on $N ranks" cmp -s b1.raw bN.raw
  check "--precision bf16 trains another model than fp32" differ b1.raw o1.raw
fi
run "$N" "$V" train vol.json -o tp "${OPTS[@]}" --target-psnr 30 -q > /dev/null 2> tp.txt
check "--target-psnr refused under mpirun with one line" grep -q "target-psnr is not supported with --bricks" tp.txt

echo "$failures failed checks"
[ $failures -eq 0 ]
