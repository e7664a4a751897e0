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
