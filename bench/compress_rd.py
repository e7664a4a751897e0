#!/usr/bin/python3
"""Rate-distortion of vnr's compact storage (`vnr train --target-ratio R`) against the peers' codecs.

Trains one model per (volume, ratio) for a fixed number of steps (quality at a fixed step count is not
noisy; the seconds are stated, the machine may be shared) and prints a markdown table of the file's
ratio, the full-volume PSNR, the held-back estimate before/after quantization and the training time.

  /usr/bin/python3 bench/compress_rd.py [--vnr build/vnr] [--data ../shared/data] [--steps 1000]
      [--ratios 32,64,128] [--volumes bonsai,chris_t1,wmag91] [--extra "--bits-per-param 4"] [--out DIR]
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--vnr", default="build/vnr")
    ap.add_argument("--data", default="../shared/data")
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--ratios", default="32,64,128")
    ap.add_argument("--volumes", default="bonsai,chris_t1,wmag91")
    ap.add_argument("--config", default="paper")
    ap.add_argument("--extra", default="", help="more `vnr train` options, e.g. '--bits-per-param 5'")
    ap.add_argument("--out", default=None, help="keep models and reports here (default: a temporary dir)")
    a = ap.parse_args()
    out = a.out or tempfile.mkdtemp(prefix="vnr_rd_")
    os.makedirs(out, exist_ok=True)
    print("| volume | target | file ratio | PSNR (dB) | held-back before / after quantization | steps | seconds |")
    print("|---|---|---|---|---|---|---|")
    for vol in a.volumes.split(","):
        sidecar = os.path.join(a.data, vol + ".json")
        if not os.path.exists(sidecar):
            print(f"compress_rd: {sidecar} not found, skipped", file=sys.stderr)
            continue
        for r in a.ratios.split(","):
            model = os.path.join(out, f"{vol}_{r}.vnr")
            report = os.path.join(out, f"{vol}_{r}.json")
            cmd = [a.vnr, "train", sidecar, "-o", model, "--config", a.config, "--target-ratio", r,
                   "--steps", str(a.steps), "--no-ssim", "--report", report, "-q"] + a.extra.split()
            subprocess.run(cmd, check=True)
            rep = json.load(open(report))
            c = rep.get("compact", {})
            print(f"| {vol} | {r}x | {rep['compression_ratio']:.1f} | {rep['psnr']:.2f} | "
                  f"{c.get('heldback_psnr_unquantized', float('nan')):.2f} / {c.get('heldback_psnr', float('nan')):.2f} | "
                  f"{rep['steps']} | {rep['seconds']:.0f} |", flush=True)


if __name__ == "__main__":
    main()
