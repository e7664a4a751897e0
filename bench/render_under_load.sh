#!/bin/sh
# Rendering that holds up where users run it (the brick-cache issue's item 4): `vnr bench render` of
# INPUT at 512x512, ray marching with macro-cells, quiet and then beside N competing single-threaded
# CPU burners of equal priority, side by side in one run; prints frames/s of each strategy and the
# ratio loaded / quiet.
#
#   sh bench/render_under_load.sh INPUT [N] [VNR]     (defaults: 1 burner, build/vnr)
set -eu
INPUT=$1
N=${2:-1}
VNR=${3:-$(dirname "$0")/../build/vnr}
OUT=$(mktemp -d)
PIDS=""
trap 'kill $PIDS 2>/dev/null || true; rm -rf "$OUT"' EXIT
run() {
  "$VNR" bench render "$INPUT" --size 512x512 --frames 20 --modes raymarch --report "$OUT/$1.json" > /dev/null
}
run quiet
i=0
while [ "$i" -lt "$N" ]; do
  sh -c 'while :; do :; done' &
  PIDS="$PIDS $!"
  i=$((i + 1))
done
run loaded
kill $PIDS
PIDS=""
/usr/bin/python3 - "$OUT" "$N" <<'PY'
import json, sys
out, n = sys.argv[1], sys.argv[2]
q, l = (json.load(open(f"{out}/{k}.json")) for k in ("quiet", "loaded"))
fps = lambda r: {row["strategy"]: row["fps"] for row in r["rows"] if row["mode"] == "raymarch" and row["macrocells"] != "off"}
fq, fl = fps(q), fps(l)
for s in fq:
    print(f"{s:10s} quiet {fq[s]:6.2f} frames/s, beside {n} burner(s) {fl.get(s, 0):6.2f} ({fl.get(s, 0) / fq[s]:.2f}x)")
PY
