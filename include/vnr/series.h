#pragma once
// Time series (paper, appendix "Adaptivity with Time-Varying Data"): the settings and results of
// training one model per timestep, warm-started, or one network across the timesteps (train/series.h
// has the rules, recovery among them), and run_series, what `vnr train --timesteps` runs.
//
// A time series trained into a directory of models, as `vnr train SERIES --timesteps` runs it (paper
// appendix "Adaptivity with Time-Varying Data"): the whole selection described before anything trains,
// then one model per timestep, warm-started (train_series), or one network trained across the timesteps
// with a model per window (train_continuous). Models go to DIR/t0000.vnr, ... (the series' timestep
// index), each written atomically as soon as it is done, and the report (DIR/series.json unless given)
// is rewritten after every model, so a failure or a stop leaves every finished model and its row on disk.
// Front ends parse and present (progress, tables) through the callbacks.
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>
#include "vnr/device.h"
#include "vnr/json.h"
#include "vnr/model.h"
#include "vnr/model_config.h"
#include "vnr/training_options.h"
#include "vnr/volume.h"

namespace vnr {

// Parses a timestep selection for a series of n_timesteps: "all", "A-B" (inclusive), "A,B,C", or a
// comma list mixing both ("0-2,5"). Timesteps come back in the order written. Errors: empty or
// malformed text, a descending range, an index outside [0, n_timesteps), a timestep listed twice.
std::vector<int> parse_timestep_selection(const std::string& spec, int n_timesteps);

// The model file name of timestep t inside an output directory: "t0000.vnr" (zero-padded to 4
// digits, more if t >= 10000). t is the series' own timestep index, not the position in the selection.
std::string timestep_model_name(int timestep, const std::string& extension = ".vnr");

// Loads timestep t (normalised, as load_volume does). Called once per timestep, in order of the
// selection, only when that timestep is needed; may throw vnr::Error. Every frame must have the
// same dims.
using FrameLoader = std::function<Volume(int timestep)>;

struct SeriesHooks {
  std::function<bool()> stop;                                          // polled after every step: true ends the run (Ctrl-C)
  std::function<void(int timestep, int64_t step, float loss)> on_step;  // step counts from 1 within the timestep / window
  std::function<void(int timestep, double load_seconds)> on_loaded;    // a timestep's volume is in memory
};

struct SeriesOptions {
  TrainOptions train;        // batch; the i-th timestep of the selection samples with seed train.seed + i
  Device device = Device::Cpu;  // the trainer's (Cuda: each timestep's volume is copied to the GPU)
  cuda::MlpPath mlp = cuda::MlpPath::Auto;
  int64_t steps = 1000;      // per timestep; < 0 = no step limit (then `seconds` must be > 0)
  int64_t warm_steps = -1;   // per warm-started timestep (-1: `steps`)
  double seconds = 0;        // wall-clock training limit per timestep (0: none)
  bool warm_start = true;    // false: every timestep restarts from init_params(init_seed) (a cold baseline)
  uint32_t init_seed = 1337; // only with warm_start = false
  int macrocell_size = 16;   // online macro-cells recorded per timestep's own training (0: none)
  bool ssim = false;         // also compute the 3-D SSIM at the end of each timestep
  CompactOptions compact;    // each timestep's model quantized for these targets (after training, no QAT)
  ErrorBoundRequest error_bound;  // each timestep's model carries the residuals that guarantee it
  double cooldown = SessionOptions{}.cooldown;  // of each timestep's budget (train/session.h)
};

struct TimestepResult {
  int timestep = 0;
  bool warm_started = false;
  int64_t steps = 0;
  double seconds = 0;       // training steps only
  double load_seconds = 0;
  float final_loss = 0;
  EvalResult eval;          // the whole volume, at voxel centres
  double lo = 0, hi = 1;    // the timestep's value range (original units)
  bool interrupted = false; // hooks.stop ended this timestep (and the run)
  std::vector<float> loss_history;
  Json compact, error_bound;  // the summaries of SeriesOptions' compact storage and error bound (null: off)
};

struct ContinuousOptions {
  TrainOptions train;                 // batch and sampling seed (one stream over the whole run)
  Device device = Device::Cpu;        // the trainer's (Cuda: the host sampler of the current timestep feeds it)
  cuda::MlpPath mlp = cuda::MlpPath::Auto;
  int64_t switch_every = 0;           // steps per timestep (> 0)
  float learning_rate = 0;            // 0: the config's (Adam's base) learning rate; never decayed
  int64_t probe_voxels = 1 << 16;     // |P|
  int64_t probe_every = 10;           // steps between probes
  uint64_t probe_seed = 0x5eed;       // which voxels P holds
  double recovery_tolerance_db = 0;   // recovered when PSNR >= psnr_before - tolerance
  int macrocell_size = 16;            // online macro-cells from each window's own samples (0: none)
  bool ssim = false;                  // 3-D SSIM in the end-of-window evaluation
};

struct ProbePoint {
  int64_t step = 0;  // global steps done when probed
  int timestep = 0;  // the timestep the probe compared against (the current target)
  double psnr = 0;
};

struct WindowResult {
  int timestep = 0;
  int64_t first_step = 0;   // global steps done before the window
  int64_t steps = 0;        // steps trained in the window
  double seconds = 0;       // training steps only
  double load_seconds = 0;
  float final_loss = 0;
  EvalResult eval;          // whole volume, after the window's last step
  double lo = 0, hi = 1;
  double psnr_end = 0;      // probe PSNR after the window's last step
  // The switch into this window (all windows but the first):
  bool has_switch = false;
  int from_timestep = -1;
  double psnr_before = 0, psnr_after = 0;
  int64_t recovery_steps = -1;   // -1: not recovered within the window
  double recovery_seconds = 0;   // valid when recovery_steps >= 0
  bool interrupted = false;
};

struct ContinuousResult {
  std::vector<WindowResult> windows;
  std::vector<ProbePoint> probes;
  std::vector<float> loss_history;           // every step of the run
  std::vector<float> learning_rate_history;  // the learning rate Adam used at every step
  float learning_rate = 0;                   // the fixed rate
  int64_t probe_voxels = 0;                  // |P| actually used
  ModelConfig config;                        // the fixed-rate config the network was trained with
};

struct SeriesRunSetup {
  // The series (volume, raw without a timestep), config, bits_per_param, target_ratio, batch, seed, steps,
  // device, mlp, precision, macrocell_size, session.output (the directory), session.cooldown and
  // session.error_bound; the sampler, checkpoints and target_psnr do not apply.
  TrainingSetup train;
  double seconds = 0;              // per timestep, when train.steps < 0
  std::string timesteps = "all";   // all | A-B | A,B,C
  bool continuous = false;         // one network across the timesteps
  int64_t switch_every = 0;        // continuous: steps per timestep
  std::string report;              // "" = DIR/series.json
  bool ssim = true;
};

struct SeriesRunCallbacks {
  SeriesHooks hooks;                                    // stop, per step, per loaded timestep
  std::function<void(const std::string& line)> note;   // what was chosen (sizing, device) before training
  // The series' first timestep and the selection, once every selected timestep was described.
  std::function<void(const VolumeDesc& first, const std::vector<int>& timesteps)> on_selection;
  std::function<void(const Json& row)> on_row;         // each saved model's report row, as it is written
};

struct SeriesRunResult {
  Json report;
  std::string report_path;
  bool interrupted = false;
  std::vector<TimestepResult> timesteps;          // per timestep
  std::optional<ContinuousResult> continuous;     // continuous
  ContinuousOptions continuous_options;
};

// The checks that need no data: one error line naming each setting as `name` spells it (default: the
// command line's options), before anything is created.
void check_series_setup(const SeriesRunSetup& s,
                        const std::function<std::string(const std::string&)>& name = option_name_of);

// Checks (check_series_setup, naming settings with `name`), describes every selected timestep, creates
// the directory and trains. A failure after some models were saved names them ("N finished models kept
// in DIR").
SeriesRunResult run_series(const SeriesRunSetup& s, const SeriesRunCallbacks& callbacks,
                           const std::function<std::string(const std::string&)>& name = option_name_of);

}  // namespace vnr
