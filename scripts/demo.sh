#!/bin/sh
# Installs dependencies, builds vnr, then compresses a generated volume into a neural
# representation and prints its PSNR and compression ratio. Needs no data beyond what it writes
# to ./out/demo.
set -eu
cd "$(dirname "$0")/.."
sh scripts/setup.sh
sh scripts/build.sh
mkdir -p out/demo
VNR=./build/vnr
$VNR synth marschner-lobb --dims 128,128,128 -o out/demo/marschner_lobb.json --force
$VNR train out/demo/marschner_lobb.json -o out/demo/marschner_lobb.vnr --target-ratio 20 --steps 500 \
  --report out/demo/train_report.json
$VNR info out/demo/marschner_lobb.vnr
$VNR decode out/demo/marschner_lobb.vnr -o out/demo/decoded.nrrd --force
# Render the network directly (no decoding) and the ground truth, and compare the two images.
$VNR render out/demo/marschner_lobb.json -o out/demo/ground_truth.png --size 512x512 --orbit 30,20 -q
$VNR render out/demo/marschner_lobb.vnr -o out/demo/neural.png --size 512x512 --orbit 30,20 \
  --reference out/demo/ground_truth.png --report out/demo/render_report.json
$VNR render out/demo/marschner_lobb.vnr -o out/demo/neural_pathtraced.png --size 512x512 --orbit 30,20 \
  --mode pathtrace --spp 8
# The same volume trained out of core: a 2 MiB block buffer (1/4 of the volume), refreshed from disk
# while it trains, with PNG previews of the model every 100 steps.
$VNR train out/demo/marschner_lobb.json -o out/demo/out_of_core.vnr --target-ratio 20 --steps 500 \
  --sampler outofcore --memory-budget 2MiB --block-dims 32,4,4 \
  --preview-every 100 --preview-dir out/demo/previews
# The same steps through the C++ library (examples/train_and_render.cpp): a program of 60 lines.
./build/example_train_and_render out/demo/marschner_lobb.json out/demo 300
echo "images in out/demo: ground_truth.png, neural.png, neural_pathtraced.png, previews/step_*.png, example.png"
