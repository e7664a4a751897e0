#!/bin/sh
# The CLI's --device cuda paths end to end against --device cpu, as a user runs them: train, eval, decode
# and render (every integrator and strategy) of one model, quantized training (--target-ratio) and the
# error bound (--max-rel-error) on the GPU trainer, multi-brick models (trained, decoded, rendered and
# evaluated on the GPU), the out-of-core sampler feeding the GPU, and time series per timestep and
# continuously. Writes OUT/cli/*.log, the reports and OUT/cli_table.md; exits non-zero when a check
# fails.
#
#   sh bench/gpu_cli.sh VNR OUT     (bench/gpu.sh runs it as its `cli` stage)
set -u
VNR=$1
W=$2/cli
mkdir -p "$W"
failed=0
# check NAME CMD...: runs CMD, logs it, says ok/FAIL with the last lines of a failure.
check() {
  name=$1
  shift
  if timeout 120 "$@" > "$W/$name.log" 2>&1; then
    echo "ok    $name"
  else
    echo "FAIL  $name (exit $?): $(tail -2 "$W/$name.log" | tr '\n' ' ')"
    failed=1
  fi
}

$VNR synth marschner-lobb --dims 96,80,64 -o "$W/ml.json" > /dev/null
M=$W/m.vnr
check train_cuda $VNR train "$W/ml.json" -o "$M" --config small --steps 1000 --device cuda --report "$W/train_cuda.json"
check train_cpu $VNR train "$W/ml.json" -o "$W/m_cpu.vnr" --config small --steps 1000 --device cpu \
  --report "$W/train_cpu.json"
check eval_cuda $VNR eval "$M" "$W/ml.json" --device cuda --report "$W/eval_cuda.json"
check eval_cpu $VNR eval "$M" "$W/ml.json" --device cpu --report "$W/eval_cpu.json"
check decode_cuda $VNR decode "$M" -o "$W/dec_cuda.raw" --dims 50,40,30 --device cuda
check decode_cpu $VNR decode "$M" -o "$W/dec_cpu.raw" --dims 50,40,30 --device cpu
for mode in raymarch shadow pathtrace; do
  check "render_cpu_$mode" $VNR render "$M" -o "$W/r_cpu_$mode.pfm" --mode $mode --size 256x192 --spp 8 --device cpu
  for strategy in streaming inshader cache; do  # cache: the GPU's copy of the brick cache
    check "render_cuda_${mode}_$strategy" $VNR render "$M" -o "$W/r_cuda_${mode}_$strategy.pfm" --mode $mode \
      --strategy $strategy --size 256x192 --spp 8 --device cuda --reference "$W/r_cpu_$mode.pfm" \
      --report "$W/render_cuda_${mode}_$strategy.json"
  done
done
check ratio_cuda $VNR train "$W/ml.json" -o "$W/r64.vnr" --config small --steps 1000 --target-ratio 64 --device cuda \
  --report "$W/ratio_cuda.json"
# --learn-steps runs on the CPU trainer only: on the GPU one clear error before any training
if $VNR train "$W/ml.json" -o "$W/ls.vnr" --config small --steps 100 --target-ratio 64 --learn-steps --device cuda \
  > "$W/learn_steps_cuda.log" 2>&1 || ! grep -q "CPU trainer only" "$W/learn_steps_cuda.log"; then
  echo "FAIL  learn_steps_cuda_refused: $(tail -2 "$W/learn_steps_cuda.log" | tr '\n' ' ')"
  failed=1
else
  echo "ok    learn_steps_cuda_refused"
fi
check bound_cuda $VNR train "$W/ml.json" -o "$W/bound.vnr" --config small --steps 1000 --max-rel-error 0.01 \
  --device cuda --report "$W/bound_cuda.json"
check bound_eval $VNR eval "$W/bound.vnr" "$W/ml.json" --device cuda --report "$W/bound_eval.json"
check bricks_cuda $VNR train "$W/ml.json" -o "$W/bricks" --bricks 2,2,1 --config small --steps 500 --device cuda \
  --report "$W/bricks_cuda.json"
check bricks_decode_cuda $VNR decode "$W/bricks" -o "$W/bdec_cuda.raw" --device cuda
check bricks_decode_cpu $VNR decode "$W/bricks" -o "$W/bdec_cpu.raw" --device cpu
check bricks_render_cpu $VNR render "$W/bricks" -o "$W/b_cpu.pfm" --size 256x192 --spp 4 --device cpu
check bricks_render_cuda $VNR render "$W/bricks" -o "$W/b_cuda.pfm" --size 256x192 --spp 4 --device cuda \
  --reference "$W/b_cpu.pfm" --report "$W/bricks_render_cuda.json"
check bricks_render_cuda_cache $VNR render "$W/bricks" -o "$W/b_cuda_cache.pfm" --size 256x192 --spp 4 --device cuda \
  --strategy cache --reference "$W/b_cpu.pfm" --report "$W/bricks_render_cuda_cache.json"
check bricks_eval_cuda $VNR eval "$W/bricks" "$W/ml.json" --device cuda --report "$W/bricks_eval.json"
check outofcore_cuda $VNR train "$W/ml.json" -o "$W/o.vnr" --sampler outofcore --memory-budget 1MiB --config small \
  --steps 1000 --device cuda --report "$W/outofcore_cuda.json"
check outofcore_cpu $VNR train "$W/ml.json" -o "$W/o_cpu.vnr" --sampler outofcore --memory-budget 1MiB --config small \
  --steps 1000 --device cpu --report "$W/outofcore_cpu.json"
$VNR synth marschner-lobb --dims 64,64,48 --timesteps 3 -o "$W/series.json" > /dev/null
check series_cuda $VNR train "$W/series.json" -o "$W/series_cuda" --timesteps 0-2 --config small --steps 500 \
  --device cuda --report "$W/series_cuda.json"
check series_cpu $VNR train "$W/series.json" -o "$W/series_cpu" --timesteps 0-2 --config small --steps 500 \
  --device cpu --report "$W/series_cpu.json"
check continuous_cuda $VNR train "$W/series.json" -o "$W/cont_cuda" --timesteps 0-2 --continuous --switch-every 300 \
  --config small --device cuda --report "$W/continuous_cuda.json"
check continuous_cpu $VNR train "$W/series.json" -o "$W/cont_cpu" --timesteps 0-2 --continuous --switch-every 300 \
  --config small --device cpu --report "$W/continuous_cpu.json"

# The table, and the GPU's results held to bounds (a wrong result fails the stage, not only a failed command):
# decodes within 2e-2 of the range of the CPU's, images at least 35 dB against the CPU's.
python3 - "$W" > "$2/cli_table.md" <<'PY'
import json, os, sys
import numpy as np
w = sys.argv[1]
bad = []
def rep(name):
    p = os.path.join(w, name + ".json")
    return json.load(open(p)) if os.path.exists(p) else {}
def raw(name):
    p = os.path.join(w, name)
    return np.fromfile(p, np.float32) if os.path.exists(p) else None
print("| check | cuda | cpu | |")
print("|---|---|---|---|")
tc, tp = rep("train_cuda"), rep("train_cpu")
print(f"| small config, 1000 steps: PSNR | {tc.get('psnr', 'n/a')} | {tp.get('psnr', 'n/a')} | "
      f"{tc.get('samples_per_second', 0) / 1e6:.1f} vs {tp.get('samples_per_second', 0) / 1e6:.1f} M samples/s |")
ec, ep = rep("eval_cuda"), rep("eval_cpu")
print(f"| eval of the GPU-trained model: PSNR / SSIM | {ec.get('psnr')} / {ec.get('ssim')} | "
      f"{ep.get('psnr')} / {ep.get('ssim')} | |")
for pre in ("dec", "bdec"):
    a, b = raw(f"{pre}_cuda.raw"), raw(f"{pre}_cpu.raw")
    if a is not None and b is not None and a.shape == b.shape:
        span = float(b.max() - b.min()) or 1.0
        d = float(np.abs(a - b).max()) / span
        print(f"| decode {pre}: max abs difference / range | {d:.2e} | | |")
        if not d <= 2e-2:
            bad.append(f"decode {pre}: {d:.2e} of the range")
for mode in ("raymarch", "shadow", "pathtrace"):
    for s in ("streaming", "inshader", "cache"):
        r = rep(f"render_cuda_{mode}_{s}")
        print(f"| render {mode} {s}: image PSNR vs the CPU | {r.get('image_psnr', 'n/a')} | | |")
        if "image_psnr" in r and not r["image_psnr"] >= 35:
            bad.append(f"render {mode} {s}: {r['image_psnr']} dB")
for name, what in (("bricks_render_cuda", "decoded"), ("bricks_render_cuda_cache", "brick cache")):
    r = rep(name)
    print(f"| multi-brick render on the GPU ({what}): image PSNR vs the CPU | {r.get('image_psnr', 'n/a')} | | |")
    if "image_psnr" in r and not r["image_psnr"] >= 35:
        bad.append(f"multi-brick render ({what}): {r['image_psnr']} dB")
for name in ("ratio_cuda", "bound_cuda", "bound_eval", "bricks_cuda", "bricks_eval"):
    r = rep(name)
    keys = {k: r[k] for k in ("psnr", "ratio", "compression_ratio", "max_error", "file_bytes") if k in r}
    if "error_bound" in r:
        keys["bound"] = {k: r["error_bound"][k] for k in ("max_error", "holds") if k in r["error_bound"]}
    print(f"| {name} | {json.dumps(keys)} | | |")
oc, op = rep("outofcore_cuda"), rep("outofcore_cpu")
print(f"| out of core, 1000 steps: PSNR | {oc.get('psnr', 'n/a')} | {op.get('psnr', 'n/a')} | "
      f"{oc.get('samples_per_second', 0) / 1e6:.1f} vs {op.get('samples_per_second', 0) / 1e6:.1f} M samples/s |")
for mode in ("series", "continuous"):
    c, p = rep(f"{mode}_cuda"), rep(f"{mode}_cpu")
    pc = [round(r.get("psnr", 0), 2) for r in c.get("rows", [])]
    pp = [round(r.get("psnr", 0), 2) for r in p.get("rows", [])]
    print(f"| time series, {mode}: PSNR per timestep | {pc} ({c.get('device')}, {c.get('total_seconds', 0):.1f} s) | "
          f"{pp} ({p.get('total_seconds', 0):.1f} s) | |")
for b in bad:
    print(f"FAIL: {b}")
sys.exit(1 if bad else 0)
PY
[ $? -eq 0 ] || failed=1
cat "$2/cli_table.md"
exit $failed
