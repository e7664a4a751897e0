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
// The settings are vnr/training_options.h's; the backends a session runs (Trainer: CPU or GPU, made by
// make_trainer) and its samplers are the train layer's (src/vnr/train), named here only.
// A time series into a directory of models, as `vnr train --timesteps`: run_series(SeriesRunSetup, callbacks).
// A setup with targets (a PSNR, a ratio, an error bound), as `vnr train` and vnr.train run it:
// train_for_targets (the size search of --target-psnr, compact storage).
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
#include "vnr/device.h"
#include "vnr/json.h"
#include "vnr/model.h"
#include "vnr/series.h"
#include "vnr/training_options.h"
#include "vnr/volume.h"

namespace vnr {

class Trainer;        // train/trainer_backend.h: a backend (CPU or GPU) running training steps
class Sampler;        // train/sampler.h: where a step's samples come from
struct TrainingData;  // train/training_data.h: the sampler and the volume or file behind it

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
  const Model& model() const { return *model_; }
  Network& network() { return *model_->net; }
  const TrainingData* data() const { return data_.get(); }
  // Seconds the out-of-core sampler's steps have waited for reads; nullopt for other training data.
  std::optional<double> io_wait_seconds() const;
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

// --target-psnr P without --target-ratio (docs/COMPRESSION.md, "Quality target"): the smallest compact
// model that reaches P. Candidates are compact files of volume bytes / R for R = 1024, 512, ..., 4; held-back
// PSNR grows with the model at equal training, so bisection finds the smallest that reaches P after
// about log2(9) ≈ 4 trainings, each of the full `steps` (or `seconds`).
struct PsnrSearch {
  std::unique_ptr<TrainingSession> session;  // the chosen model, quantized: finish() evaluates and saves it
  bool reached = false;                      // its held-back PSNR reaches the target
  bool interrupted = false;                  // a stop was requested: the search ended early
  Json tried = Json::array();                // every candidate: ratio, bytes, held-back PSNR, steps, seconds
};

// The ratios tried, smallest model first.
std::vector<double> psnr_search_ratios();

// Opens one candidate's session for a setup (open_training_session over a file or a volume in memory).
using SessionOpener = std::function<std::unique_ptr<TrainingSession>(const TrainingSetup&)>;

// setup.target_psnr > 0 and setup.target_ratio == 0. before_training(session) runs before each candidate
// trains (front ends attach their progress and stop handling there); a stop requested in a candidate ends
// the search with the best candidate so far (or that one). When no candidate reaches the target, the
// largest is returned with reached = false.
PsnrSearch search_size_for_psnr(const TrainingSetup& setup, int64_t steps, double seconds, const SessionOpener& open,
                                const MessageFn& message = {},
                                const std::function<void(TrainingSession&)>& before_training = {});

// A setup trained as `vnr train` and vnr.train train it: target_psnr alone searches sizes
// (search_size_for_psnr); otherwise one session from `open`, trained compact (train_compact: quantized,
// its last qat_fraction quantization-aware) when the setup asks for a compact model, else run().
// steps < 0: until `seconds`. before_training(session) runs before each session trains. The caller then
// finish()es the session.
struct TargetTraining {
  std::unique_ptr<TrainingSession> session;
  std::optional<PsnrSearch> search;  // target_psnr alone: the search (its session moved to `session`)
  Json compact;                      // one compact session: train_compact's summary (null otherwise)
};
TargetTraining train_for_targets(const TrainingSetup& setup, int64_t steps, double seconds, const SessionOpener& open,
                                 const MessageFn& message = {},
                                 const std::function<void(TrainingSession&)>& before_training = {});

}  // namespace vnr
