#!/bin/sh
# Re-checks the GPU claims of README ("CUDA backend") in one go on a fresh GPU machine: builds with every
# core, runs the gpu tests, compute-sanitizer (memcheck and racecheck) over them, then the benchmarks, and
# writes the logs, the JSON reports and a markdown table (OUTDIR/table.md) to OUTDIR.
#
#   sh bench/gpu.sh OUTDIR
#
# Environment (all optional):
#   VNR_VOLUME   volume to benchmark on (default: ../shared/data/bonsai.json if present, else a generated
#                256^3 Marschner-Lobb volume)
#   VNR_PEERS    folder holding torch_vnr.py (default ../shared/peers): the PyTorch peer, same GPU
#   VNR_SECONDS  seconds per benchmark (default 5)
# Without the Debian development packages installed, a folder .debs made by scripts/gpu_debs.sh is
# unpacked under /tmp/vnr-deps and used instead (GPU machines may reach no package registry).
set -eu
OUT=${1:?usage: sh bench/gpu.sh OUTDIR}
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
cd "$(dirname "$0")/.."
SECONDS_EACH=${VNR_SECONDS:-5}
CMAKE_EXTRA=""
if [ ! -f /usr/include/nlohmann/json.hpp ] && [ -d .debs ]; then
  mkdir -p /tmp/vnr-deps
  for f in .debs/*.deb; do dpkg -x "$f" /tmp/vnr-deps; done
  CMAKE_EXTRA="-DCMAKE_PREFIX_PATH=/tmp/vnr-deps/usr -DCMAKE_CXX_FLAGS=-I/tmp/vnr-deps/usr/include"
  export LD_LIBRARY_PATH="/tmp/vnr-deps/usr/lib/x86_64-linux-gnu:${LD_LIBRARY_PATH:-}"
fi
export PATH="/usr/local/cuda/bin:$PATH"
(nvidia-smi || true) > "$OUT/nvidia-smi.txt" 2>&1

echo "== configure and build (-j$(nproc))"
# shellcheck disable=SC2086
cmake -S . -B build-gpu -G Ninja -DCMAKE_BUILD_TYPE=Release -DVNR_CUDA=ON -DVNR_BUILD_BENCH=OFF $CMAKE_EXTRA \
  > "$OUT/configure.log" 2>&1 || { tail -30 "$OUT/configure.log"; exit 1; }
start=$(date +%s)
cmake --build build-gpu -j"$(nproc)" > "$OUT/build.log" 2>&1 || { tail -40 "$OUT/build.log"; exit 1; }
echo "built in $(( $(date +%s) - start ))s"
VNR=build-gpu/vnr
$VNR info | tee "$OUT/info.txt"

echo "== gpu tests"
status=0
ctest --test-dir build-gpu -L gpu --output-on-failure > "$OUT/gpu_tests.log" 2>&1 || status=1
tail -5 "$OUT/gpu_tests.log"
echo "== compute-sanitizer"
for tool in memcheck racecheck; do
  compute-sanitizer --tool $tool --error-exitcode 9 build-gpu/test_gpu > "$OUT/sanitizer_$tool.log" 2>&1 || status=1
  tail -2 "$OUT/sanitizer_$tool.log"
done

echo "== benchmarks"
VOL=${VNR_VOLUME:-}
if [ -z "$VOL" ] && [ -f ../shared/data/bonsai.json ]; then VOL=../shared/data/bonsai.json; fi
if [ -z "$VOL" ]; then
  VOL="$OUT/ml256.json"
  $VNR synth marschner-lobb --dims 256,256,256 -o "$VOL" > /dev/null
fi
for cfg in paper small; do
  for what in train infer; do
    for mlp in fused cublas; do
      $VNR bench $what "$VOL" --device cuda --config $cfg --mlp $mlp --seconds "$SECONDS_EACH" \
        --report "$OUT/${what}_${cfg}_${mlp}.json" > "$OUT/${what}_${cfg}_${mlp}.log" 2>&1 || status=1
      tail -3 "$OUT/${what}_${cfg}_${mlp}.log"
    done
  done
  $VNR bench train "$VOL" --device cpu --config $cfg --seconds 3 --report "$OUT/train_${cfg}_cpu.json" \
    > "$OUT/train_${cfg}_cpu.log" 2>&1 || true
done
# 20k steps of the paper config end to end (the paper's 3090 figure: ~32 s)
$VNR train "$VOL" -o "$OUT/paper20k.vnr" --config paper --steps 20000 --device cuda --no-ssim \
  --report "$OUT/train20k.json" > "$OUT/train20k.log" 2>&1 || status=1
tail -3 "$OUT/train20k.log"

PEERS=${VNR_PEERS:-../shared/peers}
if [ -f "$PEERS/torch_vnr.py" ]; then
  echo "== PyTorch peer on the same GPU"
  for extra in "" "--compile"; do
    tag=torch${extra:+_compile}
    python3 "$PEERS/torch_vnr.py" "$VOL" --device cuda --config paper --steps 300 $extra \
      --report "$OUT/$tag.json" > "$OUT/$tag.log" 2>&1 || true
    tail -2 "$OUT/$tag.log"
  done
fi

python3 - "$OUT" <<'PY'
import json, os, sys
out = sys.argv[1]
def load(name):
    p = os.path.join(out, name)
    return json.load(open(p)) if os.path.exists(p) else None
gpu = open(os.path.join(out, "nvidia-smi.txt")).read()
rows = []
for cfg in ("paper", "small"):
    for what in ("train", "infer"):
        for mlp in ("fused", "cublas"):
            r = load(f"{what}_{cfg}_{mlp}.json")
            if not r:
                rows.append(f"| {what} | {cfg} | {mlp} | failed | | | | |")
                continue
            res = r.get("resident_samples_per_second")
            rows.append("| {} | {} | {} | {:.1f} | {} | {:.2f} | {:.2f} | {:.0f} MiB |".format(
                what, cfg, r["mlp_path"], r["samples_per_second"] / 1e6,
                f"{res / 1e6:.1f}" if res else "", r["mlp_tflops"], r["tflops_end_to_end"],
                r["peak_gpu_memory_bytes"] / 2**20))
    c = load(f"train_{cfg}_cpu.json")
    if c:
        rows.append(f"| train | {cfg} | CPU ({c['threads']} threads) | {c['samples_per_second'] / 1e6:.2f} | | | | |")
lines = ["| mode | config | MLP | M samples/s | resident M samples/s | MLP TFLOP/s | end-to-end TFLOP/s | peak GPU memory |",
         "|---|---|---|---|---|---|---|---|"] + rows
t = load("train20k.json")
if t:
    lines.append("")
    lines.append(f"paper config, 20k steps of 65,536 samples: {t['seconds']:.2f} s "
                 f"({t['samples_per_second'] / 1e6:.1f} M samples/s), PSNR {t['psnr']:.2f} dB")
for tag in ("torch", "torch_compile"):
    r = load(f"{tag}.json")
    if r:
        lines.append(f"{tag}: {json.dumps({k: r[k] for k in r if 'per_second' in k or k in ('psnr', 'seconds')})}")
lines.append("")
lines.append("GPU: " + next((l.strip() for l in gpu.splitlines() if "NVIDIA" in l and "Driver" not in l), "see nvidia-smi.txt"))
open(os.path.join(out, "table.md"), "w").write("\n".join(lines) + "\n")
print("\n".join(lines))
PY
exit $status
