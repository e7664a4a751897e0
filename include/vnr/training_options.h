#pragma once
// The settings of a training run, one typed object per task as tiny-cuda-nn builds its objects:
// TrainingSetup (everything `vnr train VOLUME` accepts; from_json/to_json with unknown keys refused) and
// the parts it is made of (the trainer's batch and seed, the training data, the session's checkpoints and
// targets, an error bound, compact storage), and what a run reports (progress, its result).
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include "vnr/device.h"
#include "vnr/json.h"
#include "vnr/math.h"
#include "vnr/model_config.h"
#include "vnr/volume.h"

namespace vnr {

// One line for people (no trailing newline); null = say nothing.
using MessageFn = std::function<void(const std::string& line)>;

struct TrainOptions {
  int64_t batch = 65536;  // samples per step, a multiple of kChunk (256)
  uint32_t seed = 1337;   // initialisation and sampling
  // BF16: the MLP's forward and backward with bf16 operands and fp32 sums (Network::
  // mlp_forward_train_bf16; needs Network::bf16_training_supported()). The loss, the grid, the
  // master weights and Adam stay fp32.
  Precision precision = Precision::FP32;
  // Grids whose gradient takes at most this many bytes are scattered by every thread into its own
  // copy, chunk by chunk while the chunk's data is in cache, and the copies summed (faster than a
  // separate scatter pass for small grids); larger grids are scattered after the chunks,
  // each level by one thread (no private copies of tens of MiB).
  uint64_t private_grid_grad_max_bytes = uint64_t(1) << 20;
  // The step's last chunks go one at a time to whichever thread is free, so a core slowed by another
  // job does not hold the step up (each such chunk keeps its own MLP gradient, and its grid gradient
  // is scattered after the loop, so results still depend only on the thread count). 0: every chunk
  // is dealt round-robin. Not used on one thread.
  int64_t shared_tail_chunks = 64;
};

struct TrainingDataOptions {
  std::string sampler;             // incore | outofcore | mmap; "" = incore when it fits memory_budget
  uint64_t memory_budget = 0;      // bytes for the training data (> 0)
  int64_t blocks = 0, refresh = 0; // outofcore: 0 = defaults scaled to the budget
  std::optional<Int3> block_dims;  // outofcore: interior voxels of a block
  std::string grid_lr_scale = "1";  // outofcore: "auto" or a positive factor (scale_grid_learning_rate)
  uint32_t seed = 1337;            // outofcore: which blocks are loaded
  int64_t steps = -1;              // the planned steps (> 0: warn when the buffer cannot cover the volume)
  bool show_progress = false;      // progress bars on stderr for the value-range scan and the buffer fill
  // outofcore: sample only this box of the file as if it were the volume (a brick's trained box; dims,
  // coordinates and source bytes are the box's), normalised with `range` (the whole volume's, known
  // beforehand: no scan). Empty: the whole volume.
  Box3 region;
  std::optional<ValueRange> range;
};

// A guaranteed max error (--max-error in data units, --max-rel-error of the value range).
struct ErrorBoundRequest {
  double max_error = 0;
  double max_rel_error = 0;
  bool active() const { return max_error > 0 || max_rel_error > 0; }
};

struct CompactOptions {
  uint64_t target_bytes = 0;   // > 0: the model file's size (aimed just under; within -5 %..+5 %)
  double target_psnr = 0;      // > 0: the coarsest quantization whose held-back PSNR reaches this
  double qat_fraction = 0.15;  // last part of the run trained on quantized parameters
  // Rate-aware training during that part: the grid's bits (rate_term.h) weighted by rate_weight times
  // the high-rate slope 2 ln 2 * loss / parameters join the loss (0: distortion alone).
  double rate_weight = 0;
  // Learned steps during that part (train/step_learning.h): each grid level's step trains with the
  // parameters, the bits' weight following the budget; the CPU trainer only (off: it did not pay).
  bool learn_steps = false;
  int64_t probe_samples = int64_t(1) << 17;  // held-back samples for the rate-distortion choices
  // > target_bytes: the file's size when residuals (train/residuals.h) take what the network's file leaves
  // of it (--residuals auto: a network of target_bytes, the rest spent on a bound; docs/COMPRESSION.md).
  uint64_t file_bytes = 0;
  bool enabled() const { return target_bytes > 0 || target_psnr > 0; }
};

constexpr double kDefaultBitsPerParam = 4.0;

struct TrainingProgress {
  int64_t step = 0;                 // steps done in the session
  float loss = 0;                   // of the last step
  double samples_per_second = 0;    // over this run() so far
  double elapsed = 0;               // training seconds of this run() (no side work, no pauses)
};
using StepCallback = std::function<void(const TrainingProgress&)>;

struct SessionOptions {
  std::string output;            // model file for checkpoints, an error save and finish(); "" = none
  int64_t checkpoint_every = 0;  // steps between atomic model writes (0: only at the end); needs output
  // GPU: a group of steps enqueued between synchronisations never crosses a multiple of this many steps
  // of a run (0: none), so side work and callbacks see every such step (time series' probes).
  int64_t sync_every = 0;
  // The last fraction of a declared budget (set_budget) over which the learning rate falls linearly
  // toward 0: the saved parameters are then not one noisy Adam iterate (at a constant rate the PSNR of
  // the last step of a run moves by up to 0.9 dB from one step to the next; docs/COMPRESSION.md).
  // vnr's addition to tcnn's schedule; 0 keeps that schedule exactly. No effect without a budget.
  double cooldown = 0.2;
  std::string sampler_name = "incore";  // the training record's "sampler"
  // The error message of a non-finite loss; default: "training diverged at step S (loss L); try a
  // smaller learning rate".
  std::function<std::string(int64_t step, float loss)> divergence_message;
  // A guaranteed max error (--max-error/--max-rel-error): finish() adds residuals (train/residuals.h).
  ErrorBoundRequest error_bound;
  // Compact storage (--target-ratio, --target-psnr): front ends then train with train_compact()
  // (train/rate_control.h) instead of run(), and finish() saves the quantized model.
  CompactOptions compact;
};

// How finish() ends a run. The model is always finalised (a compact session quantized, the training
// record and the trainer's parameters and online ranges written into it, an error bound's residuals
// attached); then, for a session opened on training data, evaluated (exactly over a volume in memory,
// else from eval_samples random voxels, or not at all with 0) and saved to options().output.
struct FinishOptions {
  bool quantize = true;  // false: a compact session only run() keeps its network as trained (bricks)
  bool evaluate = true;
  bool ssim = true;
  int64_t eval_samples = 0;
  bool save = true;  // to options().output (a session on training data needs one; in memory: no file)
};

// What finish() measured, and the record of `vnr train --report`.
struct TrainingResult {
  int64_t steps = 0;
  double seconds = 0, samples_per_second = 0;
  float final_loss = 0;
  double psnr = 0, max_abs_error = 0, max_abs_error_original = 0;  // NaN when not evaluated
  std::optional<double> ssim;
  std::string evaluation_note;  // " (estimated from N random voxels, ...)" etc., empty for a full evaluation
  uint64_t model_bytes = 0;
  double compression_ratio = 0;
  Json report;
};

// Everything `vnr train VOLUME` needs to set a session up.
struct TrainingSetup {
  std::string volume;  // path (also its name in messages)
  RawOptions raw;
  LoadOptions load;
  // "auto" (the default: the paper's network, sized for an error bound given alone), a preset (paper,
  // small) or a tiny-cuda-nn JSON file; a named preset or file is used as given.
  std::string config = "auto";
  std::optional<Json> config_json;  // a tiny-cuda-nn config given as JSON (the Python module): wins over config
  double target_ratio = 0;       // > 0: a compact model file of volume bytes / R (within 5 %)
  double target_psnr = 0;        // > 0: the coarsest quantization reaching this PSNR (held-back estimate)
  // With target_ratio alone: "auto" lets residuals take part of the file where they decode better than a
  // network of the whole budget (config_sizing.h: residual_network_split); "off": the network takes it all.
  std::string residuals = "auto";
  double bits_per_param = kDefaultBitsPerParam;  // --target-ratio: grid sized for this many bits per parameter
  double qat_fraction = 0.15;    // compact models: last part of the steps trained quantization-aware
  double rate_weight = 0;        // compact models: weight of the rate term in that part (rate_control.h)
  bool learn_steps = false;      // compact models: the steps train in that part (train/step_learning.h; CPU)
  int64_t batch = 65536;
  uint32_t seed = 1337;
  std::string device = "auto", mlp = "auto", precision = "auto";
  std::string cpu_only_reason;  // a reason to stay on the CPU (e.g. live previews); "" = none
  int macrocell_size = 16;      // online macro-cells (0: none)
  TrainingDataOptions data;     // sampler, budget, out-of-core options (data.seed/steps are set from here)
  int64_t steps = -1;           // planned steps (coverage note only)
  SessionOptions session;

  // The settings a user gives, flat as the CLI's options (volume, config (a name or a tiny-cuda-nn
  // object), target_ratio, ..., the raw-volume keys dims/dtype/endian/offset/timestep/range, nan, the
  // sampler keys, output, checkpoint_every, cooldown, max_error, max_rel_error; docs/ARCHITECTURE.md):
  // every key optional (the defaults above), unknown keys refused with the allowed list, types and
  // ranges checked (check_training_setup's checks included, but for a CUDA device's presence).
  static TrainingSetup from_json(const Json& j);
  // Those keys: what the run was given (the training record of --report); from_json reads it back.
  Json to_json() const;
};

// The steps a run is to train, from what a front end was given (steps < 0: none; seconds <= 0: none):
// those steps, else -1 (as long as the seconds allow) when seconds are given, else kDefaultSteps.
constexpr int64_t kDefaultSteps = 1000;
inline int64_t planned_steps(int64_t steps, double seconds) {
  return steps >= 0 ? steps : (seconds > 0 ? -1 : kDefaultSteps);
}

// The checks of a setup that need no data (batch, steps, macro-cell size, out-of-core counts, a CUDA
// device when "cuda" is asked for): one error line, before anything is loaded.
void check_training_setup(const TrainingSetup& setup);

}  // namespace vnr
