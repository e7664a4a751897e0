#!/usr/bin/python3
"""PSNR against compression ratio from a `vnr bench rd --report` file, with peers' figures beside it, and
PSNR against training time beside that when the report has `--times` points (codec vnr-time).

usage: /usr/bin/python3 bench/plot_rd.py REPORT.json [REPORT2.json ...] -o RD.png [--peers bench/peers_rd.json] [--volume NAME]
The peers' curves are those of NAME (default: the report volume's file stem, e.g. bonsai); several reports
give a panel each.
"""
import argparse
import json
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

STYLE = {"vnr": ("o-", "C3"), "vnr-bound": ("*", "C3"), "zfp-rate": ("s--", "C0"), "zfp-accuracy": ("^--", "C2")}
PEER_STYLE = {"SPERR": ("P:", "k"), "TTHRESH": ("d:", "C4"), "SZ3": ("v:", "C1"), "ZFP rate": ("s:", "C0"), "ZFP accuracy": ("^:", "C2")}


def draw_rd(ax, rep, name, peers_file):
    """One report's vnr points and the peers' curves of `name` on ax."""
    for codec, (fmt, color) in STYLE.items():
        pts = sorted((p["ratio"], p["psnr"], p["parameter"]) for p in rep["points"] if p["codec"] == codec)
        if not pts:
            continue
        ax.plot([p[0] for p in pts], [p[1] for p in pts], fmt, color=color, label=f"{codec} (this run)",
                markersize=11 if codec == "vnr-bound" else 5)
        if codec == "vnr-bound":
            for r, q, b in pts:
                ax.annotate(f"|e|<={b:g}", (r, q), textcoords="offset points", xytext=(5, 5), fontsize=8)
    if peers_file:
        peers = json.load(open(peers_file))["volumes"].get(name)
        if peers:
            cur = peers["psnr_at_ratio"]
            for codec, vals in cur.items():
                if codec == "ratios" or codec.startswith("ZFP"):
                    continue
                xs = [r for r, v in zip(cur["ratios"], vals) if v is not None]
                ys = [v for v in vals if v is not None]
                fmt, color = PEER_STYLE.get(codec, ("x:", "k"))
                ax.plot(xs, ys, fmt, color=color, label=f"{codec} (peers' figures)")
            bnd = peers.get("ratio_at_bound", {})
            for b, r in zip(bnd.get("bounds", []), bnd.get("SZ3", [])):
                ax.axvline(r, color="C1", alpha=0.25, lw=1)
                ax.annotate(f"SZ3 |e|<={b:g}", (r, ax.get_ylim()[0]), rotation=90, fontsize=7, color="C1",
                            xytext=(2, 4), textcoords="offset points")
    ax.set_xscale("log", base=2)
    ax.set_xlabel("compression ratio (source bytes / compressed bytes)")
    ax.set_ylabel("PSNR (dB)")
    ax.set_title(f"rate-distortion: {name} {'x'.join(str(d) for d in rep['dims'])}")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("report", nargs="+", help="one report, or several: a panel each")
    ap.add_argument("-o", "--output", required=True)
    ap.add_argument("--peers")
    ap.add_argument("--volume", help="the peers' volume of a single report")
    a = ap.parse_args()
    reps = [json.load(open(r)) for r in a.report]
    names = [os.path.splitext(os.path.basename(r["volume"].split(":")[0]))[0] for r in reps]
    if len(reps) > 1:
        cols = 2
        rows = (len(reps) + 1) // 2
        fig, axes = plt.subplots(rows, cols, figsize=(12, 4.5 * rows), squeeze=False)
        for i, (rep, name) in enumerate(zip(reps, names)):
            draw_rd(axes[i // cols][i % cols], rep, name, a.peers)
        for i in range(len(reps), rows * cols):
            axes[i // cols][i % cols].axis("off")
        fig.tight_layout()
        fig.savefig(a.output, dpi=90)
        return
    rep, name = reps[0], a.volume or names[0]
    timed = sorted((p["parameter"], p["psnr"], p["extra"].get("wall_seconds", p["parameter"]))
                   for p in rep["points"] if p["codec"] == "vnr-time")
    if timed:
        fig, (ax, tx) = plt.subplots(1, 2, figsize=(12, 4.5), gridspec_kw={"width_ratios": [3, 2]})
    else:
        fig, ax = plt.subplots(figsize=(7, 4.5))
    draw_rd(ax, rep, name, a.peers)
    if timed:
        ratio = next(p["extra"]["target_ratio"] for p in rep["points"] if p["codec"] == "vnr-time")
        tx.plot([t[0] for t in timed], [t[1] for t in timed], "o-", color="C3", label="training budget")
        tx.plot([t[2] for t in timed], [t[1] for t in timed], "o:", color="C7", label="wall clock, every phase")
        tx.set_xscale("log")
        tx.set_xlabel("seconds")
        tx.set_ylabel("PSNR (dB)")
        tx.set_title(f"vnr at {ratio:g}x against time")
        tx.grid(True, which="both", alpha=0.3)
        tx.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(a.output, dpi=110)


if __name__ == "__main__":
    main()
