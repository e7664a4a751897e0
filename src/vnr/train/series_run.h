#pragma once
// A time series trained into a directory of models, as `vnr train SERIES --timesteps` runs it (paper
// appendix "Adaptivity with Time-Varying Data"): the whole selection described before anything trains,
// then one model per timestep, warm-started (train_series), or one network trained across the timesteps
// with a model per window (train_continuous). Models go to DIR/t0000.vnr, ... (the series' timestep
// index), each written atomically as soon as it is done, and the report (DIR/series.json unless given)
// is rewritten after every model, so a failure or a stop leaves every finished model and its row on disk.
// Front ends parse and present (progress, tables) through the callbacks.
#include <functional>
#include <optional>
#include <string>
#include <vector>
#include "vnr/json.h"
#include "vnr/train/series.h"
#include "vnr/train/session.h"

namespace vnr {

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
