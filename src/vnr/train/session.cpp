#include "vnr/train/session.h"
#include <algorithm>
#include <chrono>
#include <cmath>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/core/parallel.h"
#include "vnr/progress.h"

namespace vnr {
namespace {

using Clock = std::chrono::steady_clock;

}  // namespace

TrainingSession::TrainingSession(Model& model, std::unique_ptr<Trainer> trainer, SessionOptions opts)
    : model_(&model), trainer_(std::move(trainer)), opts_(std::move(opts)) {
  check();
}

TrainingSession::TrainingSession(Model model, std::shared_ptr<TrainingData> data, std::unique_ptr<Trainer> trainer,
                                 SessionOptions opts)
    : owned_model_(std::make_unique<Model>(std::move(model))), model_(owned_model_.get()), data_(std::move(data)),
      trainer_(std::move(trainer)), opts_(std::move(opts)) {
  check();
}

void TrainingSession::check() const {
  if (!trainer_) fail("a training session needs a trainer");
  if (!model_->net || &trainer_->network() != model_->net.get()) fail("the trainer must train the session's model");
  if (opts_.checkpoint_every < 0) fail("--checkpoint-every must be non-negative, got {}", opts_.checkpoint_every);
  if (opts_.checkpoint_every > 0 && opts_.output.empty()) fail("checkpoints need an output path");
}

std::optional<double> TrainingSession::io_wait_seconds() const {
  if (!data_ || !data_->out_of_core) return std::nullopt;
  return data_->out_of_core->io_wait_seconds();
}

TrainingSession::~TrainingSession() = default;

void TrainingSession::pause() { paused_.store(true); }

void TrainingSession::resume() {
  {
    std::lock_guard<std::mutex> lock(pause_mutex_);
    paused_.store(false);
  }
  pause_cv_.notify_all();
}

void TrainingSession::wait_while_paused() {
  std::unique_lock<std::mutex> lock(pause_mutex_);
  // request_stop() may come from a signal handler, which cannot notify: poll it.
  while (paused_.load() && !stop_requested()) pause_cv_.wait_for(lock, std::chrono::milliseconds(20));
}

void TrainingSession::run_side_work(const std::function<void()>& fn) {
  auto t0 = Clock::now();
  fn();
  side_seconds_ += seconds_since(t0);
}

float TrainingSession::step() {
  run(1);
  return loss_;
}

int64_t TrainingSession::run(int64_t steps, double seconds) {
  if (steps < 0) steps = INT64_MAX;
  int64_t done = 0;
  auto end_run = [&] {
    train_seconds_ += run_seconds_;
    run_seconds_ = 0;
  };
  try {
    run_steps(steps, seconds, &done);
  } catch (const std::exception& e) {
    // The data went away under us (or similar): keep the training done so far.
    run_seconds_ = seconds_since(run_t0_) - run_excluded_;
    if (steps_ == 0 || opts_.output.empty()) {
      end_run();
      throw;
    }
    record();
    model_->training["error"] = e.what();
    end_run();
    save_model(opts_.output, *model_);
    fail("{}; the model after {} steps was saved to {} (not evaluated)", e.what(), steps_, opts_.output);
  }
  end_run();
  return done;
}

void TrainingSession::set_budget(int64_t steps, double seconds) {
  budget_steps_ = steps;
  budget_seconds_ = seconds;
  budgeted_ = true;
  budget_first_step_ = steps_;
  budget_first_second_ = train_seconds_ + run_seconds_;
}

void TrainingSession::shorten_budget(double seconds) {
  if (budget_seconds_ > 0) budget_seconds_ = std::max(budget_seconds_ - seconds, 1e-3);
}

float TrainingSession::cooldown_multiplier() const {
  const double f = opts_.cooldown;
  if (!(f > 0)) return 1.0f;
  double p = 0;  // progress through the budget before the next step
  if (budget_steps_ > 0) p = double(steps_ - budget_first_step_) / double(budget_steps_);
  if (budget_seconds_ > 0) {
    const double t = train_seconds_ + seconds_since(run_t0_) - run_excluded_ - budget_first_second_;
    p = std::max(p, t / budget_seconds_);
  }
  if (p >= 1) return 1.0f;  // the budget is spent: later runs train at the config's rate
  return float(std::min(1.0, (1.0 - p) / f));
}

// The loop: step (GPU: a group) -> side work -> divergence check -> callbacks -> checkpoint -> limits.
void TrainingSession::run_steps(int64_t steps, double seconds, int64_t* done) {
  run_t0_ = Clock::now();
  params_frozen_ = false;
  double& excluded = run_excluded_;  // side work and pauses of this run
  excluded = 0;
  run_seconds_ = 0;
  int64_t group = 1;  // GPU: steps enqueued between synchronisations, grown to ~0.1 s
  const bool async = trainer_->asynchronous();
  const int64_t every = opts_.checkpoint_every;
  while (*done < steps && !stop_requested()) {
    if (paused_.load()) {
      auto p0 = Clock::now();
      wait_while_paused();
      excluded += seconds_since(p0);
      if (stop_requested()) break;
    }
    const auto t_step = Clock::now();
    int64_t k = async ? std::min(group, steps - *done) : 1;
    if (every > 0) k = std::min(k, every - steps_ % every);
    const float lr_mult = cooldown_multiplier();
    trainer_->set_learning_rate_multiplier(lr_mult);
    // A GPU's groups stay short in the cool-down, so its rate falls in small steps too.
    if (lr_mult < 1 && budget_steps_ > 0)
      k = std::min(k, std::max<int64_t>(1, int64_t(opts_.cooldown * double(budget_steps_) / 32)));
    if (opts_.sync_every > 0) k = std::min(k, opts_.sync_every - *done % opts_.sync_every);
    if (before_step_) before_step_();
    trainer_->run(k);
    if (after_step_) after_step_();
    loss_ = trainer_->last_loss();  // synchronises
    const double per = seconds_since(t_step) / double(k);
    for (int64_t i = 0; i < k; ++i) step_seconds_.push_back(per);
    steps_ += k;
    *done += k;
    if (async && per * double(group) < 0.1 && group < 1024) group *= 2;
    TrainingProgress p;
    p.step = steps_;
    p.loss = loss_;
    p.elapsed = run_seconds_ = seconds_since(run_t0_) - excluded;
    p.samples_per_second = double(*done) * double(trainer_->batch()) / p.elapsed;
    if (!side_work_.empty()) {
      const auto s0 = Clock::now();
      for (const StepCallback& cb : side_work_) cb(p);
      const double s = seconds_since(s0);
      excluded += s;
      side_seconds_ += s;
    }
    if (!std::isfinite(loss_))
      fail("{}", opts_.divergence_message
                     ? opts_.divergence_message(steps_, loss_)
                     : fmt::format("training diverged at step {} (loss {}); try a smaller learning rate", steps_, loss_));
    for (const StepCallback& cb : step_callbacks_) cb(p);
    if (every > 0 && steps_ % every == 0 && *done < steps) save_checkpoint();  // records run_seconds_ (= p.elapsed)
    if (seconds > 0 && p.elapsed >= seconds) break;
  }
  run_seconds_ = seconds_since(run_t0_) - excluded;
}

void TrainingSession::record() {
  const std::optional<Precision> precision = trainer_->mlp_precision();
  model_->training = {{"steps", steps_},
                      {"seconds", train_seconds_ + run_seconds_},
                      {"interrupted", stop_requested()},
                      {"batch", trainer_->batch()},
                      {"seed", trainer_->seed()},
                      {"final_loss", loss_},
                      {"threads", num_threads()},
                      {"sampler", data_ ? data_->kind : opts_.sampler_name},
                      {"device", device_name(trainer_->device())},
                      {"precision", precision ? Json(precision_name(*precision)) : Json(nullptr)}};
  if (budgeted_ && opts_.cooldown > 0) model_->training["cooldown"] = opts_.cooldown;
  if (!params_frozen_) trainer_->download();  // the model file is written from net.params()
  if (trainer_->has_online_ranges()) model_->macrocells = trainer_->online_ranges();
}

void TrainingSession::save(const std::string& path) {
  record();
  save_model(path, *model_);
}

void TrainingSession::save_checkpoint() {
  if (opts_.output.empty()) fail("checkpoints need an output path");
  record();
  model_->training["checkpoint"] = true;
  save_model(opts_.output, *model_);
}

namespace {
// The report's "error_bound" of residuals attached to a model of `volume`.
Json attached_residuals_summary(const Residuals& res, const Volume& volume) {
  Json j = residual_coding_summary(res);
  j["max_error"] = res.bound * (volume.hi - volume.lo);
  j["max_error_normalised"] = res.bound;
  j["step_normalised"] = res.step;
  j["residual_nonzero"] = res.nonzero();
  return j;
}
}  // namespace

// The error-bound residuals of the trained network (SessionOptions::error_bound), kept in the model
// (coded once here, so the save reuses the bytes); their summary for the report, or null.
Json attach_error_bound(Model& model, const Volume& volume, const ErrorBoundRequest& request) {
  const auto t0 = std::chrono::steady_clock::now();
  const double b = normalised_error_bound(request, volume.lo, volume.hi, model.source_dtype);
  // Residuals are taken against the network as the file stores it (fp16 parameters), not the fp32
  // master copy, so that a loaded model decodes to the same predictions.
  round_params_to_stored(model);
  model.residuals = smallest_residuals(*model.net, volume.data.data(), volume.dims, b);
  Json j = attached_residuals_summary(*model.residuals, volume);
  j["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return j;
}

Json attach_residuals_for_budget(Model& model, const Volume& volume, uint64_t file_bytes) {
  const auto t0 = std::chrono::steady_clock::now();
  round_params_to_stored(model);  // as attach_error_bound
  model.residuals.reset();
  const uint64_t network_bytes = model_file_bytes(model);
  // Aimed under the file's size as the network's quantization is (rate_control.cpp), less the block's
  // description (about 100 bytes in a format-3 coded header); a larger one is given back on a second try.
  const uint64_t aim = file_bytes - std::min<uint64_t>(file_bytes / 50, 256);
  uint64_t slack = 256;
  auto guaranteed = [&](double b) { return bound_after_rounding(b, volume.hi - volume.lo, model.source_dtype); };
  for (int attempt = 0; attempt < 3; ++attempt) {
    if (network_bytes + slack + aim / 16 >= aim) return Json();  // next to nothing left for residuals
    model.residuals = residuals_for_budget(*model.net, volume.data.data(), volume.dims, aim - network_bytes - slack,
                                           guaranteed);
    const uint64_t total = model_file_bytes(model);
    if (total <= aim) break;
    slack += total - aim;
    model.residuals.reset();
  }
  if (!model.residuals) return Json();
  Json j = attached_residuals_summary(*model.residuals, volume);
  j["chosen_by"] = "target_ratio";
  j["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return j;
}

Json TrainingSession::attach_residuals() {
  const bool fill = opts_.compact.file_bytes > opts_.compact.target_bytes && !opts_.error_bound.active();
  if (!opts_.error_bound.active() && !fill) return Json();
  if (!data_->vol) fail("residuals (an error bound, or --residuals with --target-ratio) need the volume in memory (in-core sampler)");
  if (fill) return attach_residuals_for_budget(*model_, *data_->vol, opts_.compact.file_bytes);
  return attach_error_bound(*model_, *data_->vol, opts_.error_bound);
}

Json TrainingSession::finalize_model(bool quantize) {
  if (!data_) {  // a model in memory (make_training_session): nothing to quantize for or measure against
    record();
    return Json();
  }
  // A compact session that was only run(): quantize now (post-training), so the file meets the target.
  if (quantize && opts_.compact.enabled() && model_->param_segments.empty()) compact_session(*this, opts_.compact, 0, 0);
  record();
  return attach_residuals();
}

TrainingResult TrainingSession::finish(const FinishOptions& o) {
  if (data_ && o.save && opts_.output.empty())
    fail("finish() needs an output path to save to (FinishOptions::save = false keeps the model in memory)");
  TrainingResult r;
  r.steps = steps_;
  r.seconds = train_seconds_;
  r.final_loss = loss_;
  r.samples_per_second = r.seconds > 0 ? double(r.steps) * double(trainer_->batch()) / r.seconds : 0.0;
  const Json bound = finalize_model(o.quantize);
  r.psnr = r.max_abs_error = r.max_abs_error_original = std::nan("");
  if (!data_) {  // a model in memory: saved only where the session was given an output
    if (o.save && !opts_.output.empty()) save_model(opts_.output, *model_);
    return r;
  }
  const TrainingData& data = *data_;
  Network& net = *model_->net;
  const Device dev = trainer_->device();
  // Exact over the volume in memory; a volume that is not in memory gets a PSNR estimate from random
  // voxels (a full pass can take longer than the training did).
  Json evaluation;
  const Residuals* residuals = model_->residuals ? &*model_->residuals : nullptr;
  if (!o.evaluate) {
    evaluation = {{"method", "none"}};
    r.evaluation_note = " (not evaluated)";
  } else if (data.vol) {
    EvalResult ev = evaluate(net, *data.vol, o.ssim, dev, residuals);
    r.psnr = ev.psnr;
    r.max_abs_error = ev.max_abs_error;
    r.max_abs_error_original = ev.max_abs_error_original;
    if (o.ssim) r.ssim = ev.ssim;
    evaluation = {{"method", "full"}};
  } else if (o.eval_samples > 0) {
    const int64_t n = std::min<int64_t>(o.eval_samples, int64_t(data.dims.count()));
    SampledEval ev = evaluate_sampled(net, data.desc, data.lo, data.hi, n, trainer_->seed() + 1, data.load, dev);
    r.psnr = ev.psnr;
    r.max_abs_error = ev.max_abs_error;
    r.max_abs_error_original = ev.max_abs_error_original;
    evaluation = {{"method", "sampled"}, {"samples", ev.samples}, {"psnr_ci95", {ev.psnr_ci95_lo, ev.psnr_ci95_hi}}};
    r.evaluation_note = fmt::format(" (estimated from {} random voxels, 95% interval {:.2f}..{:.2f}; `vnr eval` for "
                                    "the full volume)",
                                    ev.samples, ev.psnr_ci95_lo, ev.psnr_ci95_hi);
  } else {
    r.psnr = r.max_abs_error = r.max_abs_error_original = std::nan("");
    evaluation = {{"method", "none"}};
    r.evaluation_note = " (not evaluated: --eval-samples 0)";
  }
  if (std::isfinite(r.psnr)) model_->training["psnr"] = r.psnr;
  if (r.ssim) model_->training["ssim"] = *r.ssim;
  if (o.save) {
    save_model(opts_.output, *model_);
    r.model_bytes = file_size(opts_.output);
  } else {
    r.model_bytes = model_file_bytes(*model_);
  }
  r.compression_ratio = double(data.source_bytes()) / double(r.model_bytes);
  r.report = report_json(r, evaluation);
  if (!bound.is_null()) {
    // What renders: the network alone (rendering and point queries do not apply residuals).
    if (data.vol && o.evaluate) r.report["network_psnr"] = evaluate(net, *data.vol, false, dev).psnr;
    r.report["error_bound"] = bound;
    r.report["error_bound"]["holds"] = r.max_abs_error_original <= bound["max_error"].get<double>();
    r.report["error_bound"]["network_bytes"] = r.model_bytes - bound["residual_bytes"].get<uint64_t>();
  }
  if (!compact_summary_.is_null()) r.report["compact"] = compact_summary_;
  return r;
}

// The keys of `vnr train --report` (tests/test_cli.cpp and the docs rely on them).
Json TrainingSession::report_json(const TrainingResult& r, const Json& evaluation) const {
  const TrainingData& data = *data_;
  const Network& net = *model_->net;
  const std::optional<Precision> precision = trainer_->mlp_precision();
  Json report = {{"steps", r.steps},
                 {"seconds", r.seconds},
                 {"seconds_per_step", r.steps > 0 ? r.seconds / double(r.steps) : 0.0},
                 {"median_step_seconds", upper_median(step_seconds_)},
                 {"step_seconds", step_seconds_},
                 {"samples_per_second", r.samples_per_second},
                 {"final_loss", r.final_loss},
                 {"psnr", r.psnr},
                 {"ssim", r.ssim ? Json(*r.ssim) : Json(nullptr)},
                 {"evaluation", evaluation},
                 {"max_abs_error", r.max_abs_error},
                 {"n_params", net.n_params()},
                 {"model_bytes", r.model_bytes},
                 {"volume_bytes", data.source_bytes()},
                 {"compression_ratio", r.compression_ratio},
                 {"batch", trainer_->batch()},
                 {"threads", num_threads()},
                 {"sampler", data.kind},
                 {"memory_budget", data.memory_budget},
                 {"loss_history", trainer_->losses()},
                 {"device", device_name(trainer_->device())},
                 {"precision", precision ? Json(precision_name(*precision)) : Json(nullptr)},
                 {"preview_seconds", side_seconds_},
                 {"config", net.config_json()}};
  if (data.out_of_core) {
    const OutOfCoreSampler& s = *data.out_of_core;
    report["out_of_core"] = {{"blocks", s.blocks()},
                             {"refresh", s.refresh()},
                             {"block_dims", {s.block_dims().x, s.block_dims().y, s.block_dims().z}},
                             {"bytes_held", s.bytes_held()},
                             {"fill_seconds", s.fill_seconds()},
                             {"io_wait_seconds", s.io_wait_seconds()},
                             {"blocks_loaded", s.blocks_loaded()},
                             {"bytes_read", data.raw_file->bytes_read()}};
  }
  return report;
}

}  // namespace vnr
