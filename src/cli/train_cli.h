#pragma once
// `vnr train`: the options shared by single-volume training (cmd_train.cpp) and time series
// (cmd_train_series.cpp).
#include <string>
#include "cli.h"
#include "preview.h"
#include "vnr/bricks.h"
#include "vnr/trainer.h"

namespace vnr::cli {

// The options of `vnr train`: CLI11 writes the library's TrainingSetup directly (its defaults, the ones
// shown by --help), beside what only the command line has or what needs parsing first (setup_of).
struct TrainArgs {
  TrainingSetup s;  // volume, -o (session.output), --config, --target-ratio, --steps, --batch, --seed, ...
  double seconds = 0;
  std::string report;
  int threads = 0;
  bool quiet = false, no_ssim = false;
  VolumeArgs vol;
  PreviewArgs preview;  // --preview-every N --preview-dir DIR [--preview-size/-mode/-tf]
  std::string memory_budget, block_dims;    // parsed into s.data by setup_of
  int64_t eval_samples = int64_t(1) << 20;  // voxels of the final PSNR estimate when the volume is not in memory
  // Time series: "" = one volume; "all", "A-B" or "A,B,C" = those timesteps.
  std::string timesteps;
  bool continuous = false;
  int64_t switch_every = 0;  // --continuous: steps per timestep
  // Multi-brick models (issue 30, cmd_train_bricks.cpp): "" = one network; "BX,BY,BZ" or "auto".
  std::string bricks;
  int ghost = 4;
  bool resume = false;
};

// `vnr train SERIES --timesteps ... -o DIR`, with or without --continuous.
void run_train_series(const TrainArgs& a);
// `vnr train VOLUME --bricks BX,BY,BZ|auto [--ghost G] [--resume] -o DIR`: a multi-brick model.
void run_train_bricks(const TrainArgs& a);
void add_train_bricks_options(CLI::App* c, TrainArgs& a);
// `vnr info` of a multi-brick model: the lines of its bricks (describe_model's "bricks").
void print_brick_info(const Json& j);
// The setup of one training run: a.s with what needed parsing (the raw-volume options, --memory-budget,
// --block-dims) and the progress and preview choices.
TrainingSetup setup_of(const TrainArgs& a, bool preview);

}  // namespace vnr::cli
