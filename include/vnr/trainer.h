#pragma once
// vnr's training API: what `vnr train`, a viewer or the Python module drive.
//
//   TrainingSetup setup;                  // volume, config, batch, seed, device ("auto"), sampler, ...
//   setup.volume = "bonsai.json";
//   setup.session.output = "bonsai.vnr";
//   auto session = vnr::open_training_session(setup, [](const std::string& line) { log(line); });
//   session->add_step_callback([](const vnr::TrainingProgress& p) { show(p.step, p.loss); });
//   session->run(1000);                   // or run(-1, seconds); request_stop() from any thread
//   vnr::TrainingResult r = session->finish({.ssim = true, .eval_samples = 1 << 20});  // evaluate, save
//
// Lower level: make_trainer(Device, Network&, sampler, volume, options) gives a Trainer backend (CPU or
// GPU) that a TrainingSession over any Model runs; choose_training_device resolves "auto".
// A time series into a directory of models, as `vnr train --timesteps`: run_series(SeriesRunSetup, callbacks).
// A setup with targets (a PSNR, a ratio, an error bound), as `vnr train` and vnr.train run it:
// train_for_targets (the size search of --target-psnr, compact storage).
#include "vnr/train/make_trainer.h"
#include "vnr/train/psnr_search.h"
#include "vnr/train/series_run.h"
#include "vnr/train/session.h"
#include "vnr/train/trainer.h"
#include "vnr/train/trainer_backend.h"
#include "vnr/train/training_data.h"
