#pragma once
// TrainingSession: the one training loop every front end drives (`vnr train`, time series, online
// training, a viewer, the Python module). It runs a Trainer backend (CPU or GPU) on a model and:
//   - step() / run(steps, seconds): until the steps are done, the time is up or a stop is requested;
//   - pause() / resume() / request_stop(): thread-safe (request_stop is also async-signal-safe, so a
//     Ctrl-C handler may call it); a stop takes effect after the current step (GPU: step group);
//   - step callbacks with (step, loss, samples/s, elapsed training seconds), and "side work" callbacks
//     (previews, probes) whose time is left out of the training time;
//   - checkpoints: the model written atomically every N steps;
//   - the error policy: an exception after some steps saves the model so far (with the error in its
//     training record) and fails with one line saying so;
//   - finish(): the final evaluation, the model saved and the record of `vnr train --report`.
// GPU steps are enqueued in groups between synchronisations, the group doubled while it takes under
// 0.1 s, so callbacks see every group's last step.
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>
#include "vnr/json.h"
#include "vnr/train/model_io.h"
#include "vnr/train/rate_control.h"
#include "vnr/train/trainer.h"
#include "vnr/train/trainer_backend.h"
#include "vnr/train/training_data.h"

namespace vnr {

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

class TrainingSession {
public:
  // A session over `model` (its network is the trainer's), which must outlive the session.
  TrainingSession(Model& model, std::unique_ptr<Trainer> trainer, SessionOptions opts = {});
  // A session that owns its model and training data (open_training_session).
  TrainingSession(Model model, std::shared_ptr<TrainingData> data, std::unique_ptr<Trainer> trainer,
                  SessionOptions opts);
  TrainingSession(const TrainingSession&) = delete;
  TrainingSession& operator=(const TrainingSession&) = delete;
  ~TrainingSession();

  // Runs until `steps` more steps are done (< 0: no limit), `seconds` of training time have passed
  // (0: no limit) or a stop is requested. Returns the steps this call ran. One run() at a time.
  int64_t run(int64_t steps, double seconds = 0);
  // Declares the training this session is to get from now on, over any number of run() calls (< 0 /
  // 0: no limit of that kind): what options().cooldown counts its last fraction of. Once it is spent,
  // further steps train at the config's rate again.
  void set_budget(int64_t steps, double seconds);
  // Takes `seconds` off a declared seconds budget (side work that --seconds counts, e.g. quantization
  // planning), so that the cool-down still ends with the run.
  void shorten_budget(double seconds);
  float step();  // run(1); the step's loss

  void request_stop() { stop_.store(true, std::memory_order_relaxed); }
  bool stop_requested() const { return stop_.load(std::memory_order_relaxed); }
  void pause();
  void resume();
  bool paused() const { return paused_.load(); }

  // Callbacks run on the thread of run(), in the order added; add or clear them between runs only.
  void add_step_callback(StepCallback cb) { step_callbacks_.push_back(std::move(cb)); }
  void add_side_work(StepCallback cb) { side_work_.push_back(std::move(cb)); }
  void clear_callbacks() { step_callbacks_.clear(); }
  // Runs around every trainer step (one step at a time on the CPU): quantization-aware training
  // (train/rate_control.h) swaps the quantized parameters in and the master copy back. Empty: none.
  void set_step_hooks(std::function<void()> before, std::function<void()> after) {
    before_step_ = std::move(before);
    after_step_ = std::move(after);
  }
  void clear_side_work() { side_work_.clear(); }
  // Runs fn as side work (its time left out of the training time, counted in side_seconds()).
  void run_side_work(const std::function<void()>& fn);

  int64_t steps_done() const { return steps_; }
  float last_loss() const { return loss_; }
  double training_seconds() const { return train_seconds_; }  // all runs so far
  double side_seconds() const { return side_seconds_; }
  const std::vector<double>& step_seconds() const { return step_seconds_; }
  Trainer& trainer() { return *trainer_; }
  Model& model() { return *model_; }
  Network& network() { return *model_->net; }
  const TrainingData* data() const { return data_.get(); }
  const SessionOptions& options() const { return opts_; }

  // Ends a run (FinishOptions); the report of `vnr train --report` for a session on training data. A
  // later run() trains on from the model as finished.
  TrainingResult finish(const FinishOptions& options = {});
  // The model as it stands, its training record and the trainer's parameters included, written to
  // `path` while training may go on (the viewer's save).
  void save(const std::string& path);

private:
  friend Json compact_session(TrainingSession&, const CompactOptions&, int64_t, double,
                              const std::function<void(const std::string&)>&);
  // Writes the training record into model().training (steps, seconds, loss, batch, seed, sampler,
  // device, precision, interrupted) and the trainer's parameters and online ranges into the model.
  void record();
  // Declares the host parameters final (compact storage quantized them): record() and finish() no
  // longer download the trainer's copy over them, until the next run().
  void freeze_parameters() { params_frozen_ = true; }
  // The compact-storage summary (rate_control.h) that finish() puts into the report as "compact".
  const Json& note_compact(Json summary) { return compact_summary_ = std::move(summary); }
  void save_checkpoint();  // record() + "checkpoint": true, written to options().output
  // Quantizes a compact session that was only run() (with `quantize`), records, attaches the error
  // bound's residuals (returns their summary, null without a bound).
  Json finalize_model(bool quantize);

  void check() const;
  void run_steps(int64_t steps, double seconds, int64_t* done);
  float cooldown_multiplier() const;  // of the next step, from the progress through the budget
  int64_t budget_steps_ = -1, budget_first_step_ = 0;
  double budget_seconds_ = 0, budget_first_second_ = 0;
  bool budgeted_ = false;
  void wait_while_paused();
  Json report_json(const TrainingResult& r, const Json& evaluation) const;
  Json attach_residuals();

  std::unique_ptr<Model> owned_model_;
  Model* model_;
  std::shared_ptr<TrainingData> data_;
  std::unique_ptr<Trainer> trainer_;
  SessionOptions opts_;
  std::vector<StepCallback> step_callbacks_, side_work_;
  std::function<void()> before_step_, after_step_;
  bool params_frozen_ = false;
  Json compact_summary_;
  std::atomic<bool> stop_{false}, paused_{false};
  std::mutex pause_mutex_;
  std::condition_variable pause_cv_;
  int64_t steps_ = 0;
  float loss_ = 0;
  double train_seconds_ = 0, side_seconds_ = 0;
  double run_seconds_ = 0, run_excluded_ = 0;  // the current run(): training seconds, side work and pauses
  std::chrono::steady_clock::time_point run_t0_;
  std::vector<double> step_seconds_;
};

// The error bound's residuals (train/residuals.h) of `model`'s network against `volume` (normalised, in
// memory), attached to the model; the network's parameters are rounded to fp16 first, as a file stores
// them. Returns the summary that `vnr train --report` shows as "error_bound".
Json attach_error_bound(Model& model, const Volume& volume, const ErrorBoundRequest& request);
// The residuals that bring `model`'s file to file_bytes (CompactOptions::file_bytes): the finest bound
// that fits beside the network (residuals_for_budget), attached; the same summary (its "chosen_by" is
// "target_ratio"), or null when the network leaves no room.
Json attach_residuals_for_budget(Model& model, const Volume& volume, uint64_t file_bytes);

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

// A session training `model` on `volume`, held in memory (the in-core sampler; the GPU samples its own
// copy), on an explicit device; model and volume must outlive it. online_cell_size > 0 records online
// macro-cells of that many voxels (what a renderer of the model then skips empty space with).
std::unique_ptr<TrainingSession> make_training_session(Model& model, const Volume& volume, Device device,
                                                       const TrainOptions& options = {}, int online_cell_size = 16,
                                                       SessionOptions session = {});
// The same over any sampler (a time series' SwitchableSampler): the one constructor of a session over a
// model in memory, CPU and GPU alike (make_trainer). `in_memory`, when given, is the volume the GPU
// samples its own copy of; online macro-cells (over its dims, else the model's) when online_cell_size > 0.
std::unique_ptr<TrainingSession> make_training_session(Model& model, std::shared_ptr<Sampler> sampler,
                                                       const Volume* in_memory, Device device,
                                                       const TrainOptions& options, int online_cell_size,
                                                       SessionOptions session,
                                                       cuda::MlpPath mlp = cuda::MlpPath::Auto);

// Loads the config, opens the training data, sizes the model, creates it and the backend on the chosen
// device. `message` gets every line for people (volume summary, notes, the device).
std::unique_ptr<TrainingSession> open_training_session(const TrainingSetup& setup, const MessageFn& message = {});
// The same over a volume already in memory (the Python module's arrays), sampled in core and shared, not
// copied: the model, device and backend come out exactly as for a file holding the same values.
// setup.volume names it in messages; setup.raw, setup.load and setup.data's sampler options are unused.
std::unique_ptr<TrainingSession> open_training_session(const TrainingSetup& setup, std::shared_ptr<const Volume> volume,
                                                       const MessageFn& message = {});

}  // namespace vnr
