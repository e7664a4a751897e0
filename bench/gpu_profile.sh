#!/bin/sh
# Nsight Compute's speed of light of the hot kernels, for docs/benchmarks.md ("CUDA backend"): the
# kernels of paper-config training steps after warm-up, of inference (decode) and of in-shader and
# streaming ray marching at 768x768, each with its duration, its fraction of the GPU's DRAM bandwidth
# and of its SM throughput, and the tensor pipe's active fraction. Writes OUT/ncu_*.csv and
# OUT/profile.md.
#
#   sh bench/gpu_profile.sh VNR VOLUME OUT      (bench/gpu.sh runs it as its `profile` stage)
set -u
VNR=$1
VOL=$2
OUT=$3
command -v ncu > /dev/null || { echo "profile: ncu not found; skipped"; exit 0; }
# the tensor pipe's metric name differs between chips and ncu versions: take the first this one knows
ncu --query-metrics > "$OUT/ncu_metrics.txt" 2>&1 || true
TENSOR=""
for m in sm__pipe_tensor_op_gmma_cycles_active sm__pipe_tensor_op_hmma_cycles_active sm__pipe_tensor_cycles_active \
  sm__inst_executed_pipe_tensor_op_hmma; do
  if grep -q "^$m " "$OUT/ncu_metrics.txt"; then TENSOR=$m.avg.pct_of_peak_sustained_active; break; fi
done
METRICS="gpu__time_duration.sum,dram__throughput.avg.pct_of_peak_sustained_elapsed,sm__throughput.avg.pct_of_peak_sustained_elapsed,l1tex__throughput.avg.pct_of_peak_sustained_elapsed${TENSOR:+,$TENSOR}"
timeout 90 $VNR train "$VOL" -o "$OUT/profile.vnr" --config paper --steps 1000 --device cuda --no-ssim -q \
  > "$OUT/profile_train.log" 2>&1
run() {  # run NAME SKIP COUNT CMD...
  name=$1 skip=$2 count=$3
  shift 3
  timeout 120 ncu --metrics "$METRICS" --launch-skip "$skip" --launch-count "$count" --csv "$@" \
    > "$OUT/ncu_$name.csv" 2> "$OUT/ncu_$name.err" || echo "profile $name: ncu failed: $(tail -2 "$OUT/ncu_$name.err")"
}
run train 400 40 $VNR train "$VOL" -o /tmp/ncu.vnr --config paper --steps 60 --device cuda --no-ssim -q
run decode 0 20 $VNR decode "$OUT/profile.vnr" -o /tmp/ncu_dec.raw --device cuda --force -q
run inshader 0 30 $VNR render "$OUT/profile.vnr" -o /tmp/ncu_i.png --size 768x768 --strategy inshader --device cuda -q
run streaming 0 60 $VNR render "$OUT/profile.vnr" -o /tmp/ncu_s.png --size 768x768 --strategy streaming --device cuda -q
python3 - "$OUT" "$TENSOR" <<'PY' | tee "$OUT/profile.md"
import csv, collections, io, os, sys
out, tensor = sys.argv[1], sys.argv[2]
cols = {"gpu__time_duration.sum": "us", "dram__throughput.avg.pct_of_peak_sustained_elapsed": "DRAM %",
        "sm__throughput.avg.pct_of_peak_sustained_elapsed": "SM %",
        "l1tex__throughput.avg.pct_of_peak_sustained_elapsed": "L1 %"}
if tensor:
    cols[tensor] = "tensor %"
for name in ("train", "decode", "inshader", "streaming"):
    p = os.path.join(out, f"ncu_{name}.csv")
    if not os.path.exists(p):
        continue
    text = open(p).read()
    text = text[text.find('"ID"'):] if '"ID"' in text else ""
    agg = collections.defaultdict(lambda: collections.defaultdict(list))
    for row in csv.DictReader(io.StringIO(text)):
        if row.get("Metric Name") in cols:
            v = float(row["Metric Value"].replace(",", "") or 0)
            if row["Metric Name"] == "gpu__time_duration.sum":  # to microseconds
                v *= {"ns": 1e-3, "nsecond": 1e-3, "ms": 1e3, "msecond": 1e3, "s": 1e6, "second": 1e6}.get(row.get("Metric Unit"), 1)
            agg[row["Kernel Name"][:60]][cols[row["Metric Name"]]].append(v)
    print(f"### {name}\n")
    print("| kernel | launches | mean us | " + " | ".join(c for c in cols.values() if c != "us") + " |")
    print("|---|---|---|" + "---|" * (len(cols) - 1))
    for k, m in sorted(agg.items(), key=lambda kv: -sum(kv[1]["us"])):
        n = len(m["us"])
        rest = " | ".join(f"{sum(m[c]) / max(len(m[c]), 1):.1f}" for c in cols.values() if c != "us")
        print(f"| `{k}` | {n} | {sum(m['us']) / max(n, 1):.1f} | {rest} |")
    print()
PY
