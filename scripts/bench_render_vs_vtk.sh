#!/bin/sh
# Side-by-side rendering benchmark against VTK's CPU ray caster (vtkFixedPointVolumeRayCastMapper), in
# one run so both see the same machine load. Same volume, 512x512, 1-voxel uniform steps, no shading,
# the VTK peer's transfer function ("ramp" preset) and its camera (ResetCamera framing, 30 degrees,
# orbiting 360 degrees about +y over the timed frames).
#
#   scripts/bench_render_vs_vtk.sh VOLUME.json [MODEL.vnr] [FRAMES]
#
# Needs the VTK peer script vtk_raycast.py (by default from the project's shared folder beside the
# repository, ../shared/peers; or VNR_VTK_PEER=path) and its Debian packages:
#   apt-get install python3-vtk9 xvfb xauth libgl1-mesa-dri
set -eu
VOL=${1:?usage: $0 VOLUME.json [MODEL.vnr] [FRAMES]}
MODEL=${2:-}
FRAMES=${3:-36}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
VNR=${VNR:-$ROOT/build/vnr}
PEER=${VNR_VTK_PEER:-$ROOT/../shared/peers/vtk_raycast.py}
OUT=${OUT:-$(mktemp -d)}
mkdir -p "$OUT"
THREADS=${THREADS:-$(nproc)}
[ -x "$VNR" ] || { echo "build vnr first (scripts/build.sh)" >&2; exit 1; }
[ -f "$PEER" ] || { echo "VTK peer not found at $PEER" >&2; exit 1; }

echo "== VTK vtkFixedPointVolumeRayCastMapper ($THREADS threads)"
xvfb-run -a -s "-screen 0 1024x768x24" /usr/bin/python3 "$PEER" "$VOL" --mapper fixed --size 512x512 \
  --frames "$FRAMES" --warmup 3 --threads "$THREADS" --report "$OUT/vtk.json" --png "$OUT/vtk.png" | tail -n 3
echo "== vnr, ground-truth grid"
"$VNR" bench render "$VOL" --size 512x512 --frames "$FRAMES" --warmup 3 --modes raymarch --step 1 --step-max 1 --macrocell-size 8 \
  --threads "$THREADS" --report "$OUT/vnr_grid.json"
echo "== vnr, ground-truth grid, in-shader with the per-ray loop (--ray-packets off, the portable reference)"
"$VNR" bench render "$VOL" --size 512x512 --frames "$FRAMES" --warmup 3 --modes raymarch --strategies inshader --step 1 \
  --step-max 1 --macrocell-size 8 --ray-packets off --threads "$THREADS" --report "$OUT/vnr_grid_per_ray.json"
if [ -n "$MODEL" ]; then
  echo "== vnr, neural model (its ground truth for the grid macro-cells: $VOL)"
  "$VNR" bench render "$MODEL" --volume "$VOL" --size 512x512 --frames "${MODEL_FRAMES:-6}" --warmup 1 --modes raymarch --macrocell-size 8 \
    --step 1 --step-max 1 --threads "$THREADS" --report "$OUT/vnr_model.json"
fi
echo "reports in $OUT"
