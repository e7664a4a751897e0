#!/bin/sh
# The vs-PyTorch table of docs/benchmarks.md ("Against the PyTorch reference (CPU)"): ROUNDS runs of
# the side-by-side script (vnr and the PyTorch reference trainer, 2 threads each), then per row the
# range and the median of vnr's rate, the peer's and their ratio. A shared VM's speed moves within
# minutes, and vnr and the peer do not move together, so one round says little and a median more.
#
#   sh bench/vs_peer_rounds.sh [ROUNDS] [VNR] [VOLUME.json]
#   defaults: 5 rounds, build/vnr, the side-by-side script's default volume (bonsai)
# Needs the project's shared folder checked out beside the repository (../shared): its tools/vs_peer.sh,
# the PyTorch reference trainer and the Debian packages that trainer runs on.
set -eu
ROUNDS=${1:-5}
VNR=${2:-$(dirname "$0")/../build/vnr}
SCRIPT=$(dirname "$0")/../../shared/tools/vs_peer.sh
[ -f "$SCRIPT" ] || { echo "vs_peer_rounds: $SCRIPT not found (needs ../shared beside the repository)" >&2; exit 1; }
[ -x "$VNR" ] || { echo "vs_peer_rounds: no vnr binary at $VNR (build first, or pass its path)" >&2; exit 1; }
LOG=$(mktemp)
trap 'rm -f "$LOG"' EXIT
i=1
while [ "$i" -le "$ROUNDS" ]; do
  echo "round $i of $ROUNDS ($(date -u +%H:%M:%S) UTC)" >&2
  bash "$SCRIPT" "$VNR" ${3:+"$3"} | tee -a "$LOG" >&2
  i=$((i + 1))
done
/usr/bin/python3 - "$LOG" <<'EOF'
import statistics, sys
rows = {}
for line in open(sys.argv[1]):
    f = line.split()
    if len(f) == 5 and f[4].endswith("x") and f[0] in ("paper", "small"):
        rows.setdefault((f[0], f[1]), []).append((float(f[2]), float(f[3]), float(f[4][:-1])))
print("| config | mode | vnr M samples/s | PyTorch M samples/s | ratio (median) | rounds |")
print("|---|---|---|---|---|---|")
for (cfg, mode), r in rows.items():
    v, p, q = ([x[k] for x in r] for k in range(3))
    print(f"| {cfg} | {mode} | {min(v):.3g} – {max(v):.3g} | {min(p):.3g} – {max(p):.3g} | "
          f"{min(q):.1f}x – {max(q):.1f}x ({statistics.median(q):.1f}x) | {len(r)} |")
EOF
