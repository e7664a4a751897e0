#pragma once
// `vnr train`: the options shared by single-volume training (cmd_train.cpp) and time series
// (cmd_train_series.cpp).
#include <string>
#include "cli.h"
#include "preview.h"
#include "vnr/train/bricks.h"
#include "vnr/train/session.h"
#include "vnr/train/training_data.h"

namespace vnr::cli {

struct TrainArgs {
  std::string volume, output, config = TrainingSetup{}.config, report;
  double target_ratio = 0, seconds = 0;
  double max_error = 0, max_rel_error = 0;  // error-bound residuals (0: none)
  double target_psnr = 0;  // compact storage (train/rate_control.h)
  double bits_per_param = TrainingSetup{}.bits_per_param, qat_fraction = TrainingSetup{}.qat_fraction;
  double rate_weight = TrainingSetup{}.rate_weight;
  std::string residuals = TrainingSetup{}.residuals;  // --target-ratio: auto | off
  double cooldown = SessionOptions{}.cooldown;  // fraction of the budget with a falling learning rate
  int64_t steps = -1, batch = TrainingSetup{}.batch;
  uint32_t seed = TrainingSetup{}.seed;
  int threads = 0;
  int macrocell_size = TrainingSetup{}.macrocell_size;
  bool quiet = false, no_ssim = false;
  std::string device = TrainingSetup{}.device, mlp = TrainingSetup{}.mlp;  // backend; MLP path on the GPU
  std::string precision = TrainingSetup{}.precision;                      // CPU: the MLP's training arithmetic
  VolumeArgs vol;
  PreviewArgs preview;  // --preview-every N --preview-dir DIR [--preview-size/-mode/-tf]
  // Samplers (issue 4): incore | outofcore | mmap; "" = incore when the volume fits the budget.
  std::string sampler, memory_budget, block_dims;
  int64_t blocks = 0, refresh = 0;  // 0 = defaults scaled to the budget
  std::string grid_lr_scale = "1";  // outofcore: factor on the grid's learning rate ("auto" or a number)
  int64_t eval_samples = int64_t(1) << 20;  // voxels of the final PSNR estimate when the volume is not in memory
  int64_t checkpoint_every = 0;     // steps between atomic model writes (0: only at the end)
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
// `vnr info` of a multi-brick model: the bricks into the JSON (totals of parameters), and their lines.
void add_brick_info(const Model& m, Json& j);
void print_brick_info(const Json& j);
// The setup of one training run from the arguments (cmd_train.cpp).
TrainingSetup setup_of(const TrainArgs& a, bool preview);

}  // namespace vnr::cli
