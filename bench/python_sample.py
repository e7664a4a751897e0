#!/usr/bin/env python3
"""Model.sample() throughput against `vnr bench infer`, side by side (median of N runs each).

Both infer the same config on the same threads: the CLI times batches of 65536 random points through
a fresh model of the config; the module times sample() on --points random points (one call, batched
inside) through a model of the same config trained for one step on the same volume.

  PYTHONPATH=build/python /usr/bin/python3 bench/python_sample.py --cli build/vnr [--volume V.json]
"""
import argparse
import json
import os
import statistics
import subprocess
import tempfile
import time

import numpy as np
import vnr


def cli_rate(cli, volume, config, threads, seconds, device):
    with tempfile.TemporaryDirectory() as d:
        report = os.path.join(d, "r.json")
        subprocess.run([cli, "bench", "infer", volume, "--config", config, "--threads", str(threads), "--seconds",
                        str(seconds), "--device", device, "--report", report], check=True, capture_output=True)
        with open(report) as f:
            return json.load(f)["samples_per_second"]


def module_rate(model, points, device):
    t0 = time.perf_counter()
    model.sample(points, device=device)
    return len(points) / (time.perf_counter() - t0)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--cli", default=os.environ.get("VNR_CLI", "build/vnr"))
    p.add_argument("--volume", help="volume file (default: a generated 64^3 noise volume)")
    p.add_argument("--config", default="paper")
    p.add_argument("--threads", type=int, default=os.cpu_count())
    p.add_argument("--points", type=float, default=1e7)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--seconds", type=float, default=3, help="timed duration of each `vnr bench infer`")
    p.add_argument("--device", default="cpu")
    a = p.parse_args()
    with tempfile.TemporaryDirectory() as d:
        volume = a.volume
        if not volume:
            volume = os.path.join(d, "noise.json")
            subprocess.run([a.cli, "synth", "noise", "--dims", "64,64,64", "-o", volume], check=True,
                           capture_output=True)
        vnr.set_num_threads(a.threads)
        model = vnr.train(volume, config=a.config, steps=1, device=a.device, threads=a.threads)
        points = np.random.default_rng(0).random((int(a.points), 3), dtype=np.float32)
        module_rate(model, points[:65536], a.device)  # warm-up
        cli, mod = [], []
        for _ in range(a.repeats):  # alternating, so that a busy machine slows both alike
            cli.append(cli_rate(a.cli, volume, a.config, a.threads, a.seconds, a.device))
            mod.append(module_rate(model, points, a.device))
    c, m = statistics.median(cli), statistics.median(mod)
    print(f"config {a.config}, {a.threads} threads, device {a.device}, {len(points):.0e} points")
    print(f"vnr bench infer : {c / 1e6:8.2f} M samples/s  (runs: {', '.join(f'{r / 1e6:.2f}' for r in cli)})")
    print(f"Model.sample()  : {m / 1e6:8.2f} M samples/s  (runs: {', '.join(f'{r / 1e6:.2f}' for r in mod)})")
    print(f"ratio           : {100 * m / c:8.1f} %")


if __name__ == "__main__":
    main()
