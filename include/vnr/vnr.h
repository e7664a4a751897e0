#pragma once
// vnr's public C++ API: the objects every front end (the `vnr` CLI, the viewer, the Python module)
// drives. Include this one header; examples/train_and_render.cpp walks through it, and
// docs/ARCHITECTURE.md ("Public API") says what each object is for.
//   Volume    open any supported source or wrap an array; value range; lookup view   (vnr/volume.h)
//   Model     create from a typed config, load/save, query points, decode, evaluate   (vnr/model.h)
//   TrainingSession  the one training loop, on a CPU or GPU Trainer backend           (vnr/trainer.h)
//   Renderer  camera, transfer function, mode, strategy, macro-cells; progressive     (vnr/renderer.h)
//   OnlineLoop  training steps and frames of one model interleaved                    (vnr/online.h)
//   benchmark_training / benchmark_inference: what `vnr bench train|infer` measures  (vnr/benchmark.h)
#include "vnr/version.h"
#include "vnr/volume.h"
#include "vnr/model.h"
#include "vnr/trainer.h"
#include "vnr/renderer.h"
#include "vnr/online.h"
#include "vnr/benchmark.h"
