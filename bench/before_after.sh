#!/bin/sh
# Two vnr builds side by side on one volume: `vnr bench train|infer` (paper and small configs) and
# `vnr bench render` (a model trained by the OLD build, rendered by both), alternating OLD and NEW in
# every round so that the machine's drift hits both alike. Prints per row the medians and NEW/OLD, and
# the training step's phases (ms) where the builds time them.
#
#   sh bench/before_after.sh OLD_VNR NEW_VNR VOLUME.json [ROUNDS] [THREADS|cuda]
#   e.g. sh bench/before_after.sh ../before/build/vnr build/vnr bonsai.json 5 2
# THREADS = cuda runs both on the GPU (--device cuda; rendering at 768x768 in-shader, ray marching and
# shadows, a 2000-step model with macro-cells): bench/gpu.sh's `before` stage.
set -eu
OLD=$1 NEW=$2 VOL=$3 ROUNDS=${4:-5} THREADS=${5:-2}
for b in "$OLD" "$NEW"; do [ -x "$b" ] || { echo "before_after: no vnr binary at $b" >&2; exit 1; }; done
DIR=$(mktemp -d)
trap 'rm -rf "$DIR"' EXIT
# shellcheck disable=SC2086  # ON and RENDER are lists of options
if [ "$THREADS" = cuda ]; then
  ON="--device cuda"
  "$OLD" train "$VOL" -o "$DIR/model.vnr" --config paper --steps 2000 $ON --macrocell-size 16 --no-ssim -q >/dev/null
  RENDER="--size 768x768 --frames 12 --warmup 2 --strategies inshader --modes raymarch,shadow"
else
  ON="--threads $THREADS"
  "$OLD" train "$VOL" -o "$DIR/model.vnr" --config paper --steps 300 $ON -q >/dev/null
  RENDER="--size 256x256 --frames 6 --warmup 1 --modes raymarch,pathtrace"
fi
i=1
while [ "$i" -le "$ROUNDS" ]; do
  echo "round $i of $ROUNDS" >&2
  for side in old new; do
    [ "$side" = old ] && B=$OLD || B=$NEW
    for cfg in paper small; do
      for what in train infer; do
        # shellcheck disable=SC2086
        "$B" bench "$what" "$VOL" --config "$cfg" --seconds ${BENCH_SECONDS:-4} $ON \
          --report "$DIR/$side.$cfg.$what.$i.json" >/dev/null 2>&1
      done
    done
    # shellcheck disable=SC2086
    "$B" bench render "$DIR/model.vnr" $RENDER $ON --report "$DIR/$side.render.$i.json" >/dev/null 2>&1
  done
  i=$((i + 1))
done
/usr/bin/python3 - "$DIR" <<'EOF'
import glob, json, statistics, sys
d = sys.argv[1]
def med(side, key_fn, pattern):
    vals = {}
    for f in sorted(glob.glob(f"{d}/{side}.{pattern}.*.json")):
        for k, v in key_fn(json.load(open(f))):
            vals.setdefault(k, []).append(v)
    return {k: statistics.median(v) for k, v in vals.items()}
rows = []
for cfg in ("paper", "small"):
    for what in ("train", "infer"):
        fn = lambda j: [((cfg, what), j["samples_per_second"] / 1e6)]
        o, n = med("old", fn, f"{cfg}.{what}"), med("new", fn, f"{cfg}.{what}")
        rows += [(f"bench {what} --config {cfg} (M samples/s)", o[(cfg, what)], n[(cfg, what)])]
        if what == "train":  # the step's phases, by key (their names may differ between the builds)
            ph = lambda j: [((cfg, k), v) for k, v in j.get("phase_ms", {}).items()]
            o, n = med("old", ph, f"{cfg}.{what}"), med("new", ph, f"{cfg}.{what}")
            rows += [(f"  {cfg} step phase {k[1]} (ms)", o.get(k, float("nan")), n.get(k, float("nan")))
                     for k in sorted(set(o) | set(n))]
fn = lambda j: [((r["mode"], r["strategy"], r["macrocells"]), r["fps"]) for r in j["rows"]]
o, n = med("old", fn, "render"), med("new", fn, "render")
for k in o:
    rows.append((f"bench render {' / '.join(k)} (frames/s)", o[k], n.get(k, float("nan"))))
print("| measurement | before (median) | after (median) | after / before |")
print("|---|---|---|---|")
for name, a, b in rows:
    print(f"| {name} | {a:.3g} | {b:.3g} | {b / a:.2f} |")
EOF
