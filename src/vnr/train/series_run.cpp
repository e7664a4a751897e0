#include "vnr/series.h"
#include "vnr/train/series.h"
#include "vnr/train/session.h"
#include <chrono>
#include <filesystem>
#include <memory>
#include <system_error>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/progress.h"
#include "vnr/threads.h"
#include "vnr/model_config.h"
#include "vnr/train/config_sizing.h"
#include "vnr/train/make_trainer.h"
#include "vnr/train/model_io.h"

namespace vnr {
namespace {

namespace fs = std::filesystem;

void write_report(const std::string& path, const Json& report) { write_file_atomic(path, report.dump(2) + "\n"); }

void make_output_dir(const std::string& dir) {
  std::error_code ec;
  if (fs::is_directory(dir, ec)) return;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir)) fail("cannot create output directory '{}': {}", dir, ec ? ec.message() : "unknown error");
}

// One run: what both modes share, and the save and report policy.
struct SeriesRun {
  SeriesRun(const SeriesRunSetup& setup, const SeriesRunCallbacks& cb, Model m, std::vector<int> timesteps)
      : s(setup), callbacks(cb), model(std::move(m)), ts(std::move(timesteps)) {}
  const SeriesRunSetup& s;
  const SeriesRunCallbacks& callbacks;
  Model model;
  std::vector<int> ts;
  FrameLoader load;
  SeriesRunResult result;
  uint64_t frame_bytes = 0;
  Precision precision = Precision::FP32;
  Device device = Device::Cpu;
  std::chrono::steady_clock::time_point t_all;
  int saved = 0;

  const std::string& dir() const { return s.train.session.output; }
  TrainOptions train_options() const {
    TrainOptions t{s.train.batch, s.train.seed};
    t.precision = precision;
    return t;
  }
  // Saves the model of r's timestep (a TimestepResult or a WindowResult) and returns its report row
  // with the keys both modes share.
  template <class Result>
  Json save(const Model& m, const Result& r) {
    const std::string path = join_path(dir(), timestep_model_name(r.timestep));
    save_model(path, m);
    ++saved;
    const uint64_t bytes = file_size(path);
    return {{"timestep", r.timestep},
            {"model", path},
            {"steps", r.steps},
            {"seconds", r.seconds},
            {"load_seconds", r.load_seconds},
            {"final_loss", r.final_loss},
            {"lo", r.lo},
            {"hi", r.hi},
            {"model_bytes", bytes},
            {"compression_ratio", double(frame_bytes) / double(bytes)},
            {"interrupted", r.interrupted},
            {"psnr", r.eval.psnr},
            {"ssim", s.ssim ? Json(r.eval.ssim) : Json(nullptr)},
            {"max_abs_error", r.eval.max_abs_error},
            {"max_abs_error_original", r.eval.max_abs_error_original}};
  }
  // Appends a row and rewrites the report, marked incomplete until finish().
  void add_row(Json row) {
    result.report["rows"].push_back(row);  // one per saved model
    result.report["complete"] = false;
    write_report(result.report_path, result.report);
    if (callbacks.on_row) callbacks.on_row(row);
  }
  void finish(bool interrupted) {
    result.interrupted = interrupted;
    result.report["interrupted"] = interrupted;
    result.report["complete"] = !interrupted;
    result.report["total_seconds"] = seconds_since(t_all);
    write_report(result.report_path, result.report);
  }
};

// One model per timestep, warm-started (train_series: a TrainingSession per timestep).
void train_per_timestep(SeriesRun& run) {
  const SeriesRunSetup& s = run.s;
  SeriesOptions so;
  so.train = run.train_options();
  so.device = run.device;
  so.mlp = cuda::parse_mlp_path(s.train.mlp);
  so.steps = planned_steps(s.train.steps, s.seconds);
  so.cooldown = s.train.session.cooldown;
  so.seconds = s.seconds;
  so.macrocell_size = s.train.macrocell_size;
  so.ssim = s.ssim;
  if (s.train.target_ratio > 0) so.compact.target_bytes = uint64_t(double(run.frame_bytes) / s.train.target_ratio);
  so.error_bound = s.train.session.error_bound;
  run.result.report["steps_per_timestep"] = so.steps >= 0 ? Json(so.steps) : Json(nullptr);
  run.result.report["seconds_per_timestep"] = s.seconds;
  run.result.report["config"] = run.model.net->config_json();
  run.result.report["precision"] = precision_name(run.precision);
  auto done = [&](const TimestepResult& r, const Model& m) {
    Json row = run.save(m, r);
    row["warm_start"] = r.warm_started;
    if (!r.compact.is_null()) row["compact"] = r.compact;
    if (!r.error_bound.is_null()) {
      row["error_bound"] = r.error_bound;
      row["error_bound"]["holds"] = r.eval.max_abs_error_original <= r.error_bound["max_error"].get<double>();
    }
    run.add_row(std::move(row));
  };
  run.result.timesteps = train_series(run.model, run.ts, run.load, so, run.callbacks.hooks, done);
  run.finish(!run.result.timesteps.empty() && run.result.timesteps.back().interrupted);
}

// The switch into a window of continuous training, for its report row (null for the first window).
Json switch_json(const WindowResult& w) {
  if (!w.has_switch) return nullptr;
  return {{"from", w.from_timestep},
          {"psnr_before", w.psnr_before},
          {"psnr_after", w.psnr_after},
          {"recovered", w.recovery_steps >= 0},
          {"recovery_steps", w.recovery_steps >= 0 ? Json(w.recovery_steps) : Json(nullptr)},
          {"recovery_seconds", w.recovery_steps >= 0 ? Json(w.recovery_seconds) : Json(nullptr)}};
}

// One network trained across the timesteps (train_continuous: one TrainingSession for the run).
void train_continuously(SeriesRun& run) {
  const SeriesRunSetup& s = run.s;
  ContinuousOptions& co = run.result.continuous_options;
  co.train = run.train_options();
  co.device = run.device;
  co.mlp = cuda::parse_mlp_path(s.train.mlp);
  co.switch_every = s.switch_every;
  co.macrocell_size = s.train.macrocell_size;
  co.ssim = s.ssim;
  auto done = [&](const WindowResult& w, const Model& m) {
    Json row = run.save(m, w);
    row["first_step"] = w.first_step;
    row["probe_psnr_end"] = w.psnr_end;
    row["switch"] = switch_json(w);
    run.result.report["switch_every"] = s.switch_every;
    run.result.report["learning_rate"] = m.net->config().adam.learning_rate;
    run.result.report["config"] = m.net->config_json();
    run.result.report["precision"] = precision_name(run.precision);
    run.add_row(std::move(row));
  };
  const ContinuousResult& res = run.result.continuous.emplace(
      train_continuous(run.model, run.ts, run.load, co, run.callbacks.hooks, done));
  Json probes = Json::array();
  for (const ProbePoint& p : res.probes) probes.push_back({p.step, p.timestep, p.psnr});
  run.result.report["probe_voxels"] = res.probe_voxels;
  run.result.report["probe_every"] = co.probe_every;
  run.result.report["recovery_tolerance_db"] = co.recovery_tolerance_db;
  run.result.report["probes"] = probes;
  run.result.report["loss_history"] = res.loss_history;
  run.finish(!res.windows.empty() && res.windows.back().interrupted);
}

}  // namespace

void check_series_setup(const SeriesRunSetup& s, const std::function<std::string(const std::string&)>& name) {
  TrainingSetup shared;  // batch, steps and macro-cell size: checked as for one volume
  shared.batch = s.train.batch;
  shared.steps = s.train.steps;
  shared.macrocell_size = s.train.macrocell_size;
  check_training_setup(shared);
  if (s.seconds < 0) fail("{} must not be negative, got {}", name("seconds"), s.seconds);
  if (s.train.raw.timestep)
    fail("{} picks one timestep of a single-volume run; with {} give the selection there (e.g. {} {})",
         name("timestep"), name("timesteps"), name("timesteps"), *s.train.raw.timestep);
  if (s.continuous) {
    if (s.switch_every <= 0)
      fail("{} needs {} N (training steps per timestep, N > 0), got {}", name("continuous"), name("switch_every"),
           s.switch_every);
    if (s.train.steps >= 0 || s.seconds > 0)
      fail("{} trains {} steps per timestep; {} and {} do not apply", name("continuous"), name("switch_every"),
           name("steps"), name("seconds"));
    if (s.train.target_ratio > 0 || s.train.session.error_bound.active())
      fail("{}, {} and {} make per-timestep models; not with {}", name("target_ratio"), name("max_error"),
           name("max_rel_error"), name("continuous"));
  } else if (s.switch_every != 0) {
    fail("{} needs {}", name("switch_every"), name("continuous"));
  }
  if (s.train.target_psnr > 0) fail("{} is not supported with {} (no size search per timestep)", name("target_psnr"), name("timesteps"));
  const std::string& sampler = s.train.data.sampler;
  if (!sampler.empty() && sampler != "incore")
    fail("{} {} is not supported with {} (each timestep is trained in memory)", name("sampler"), sampler,
         name("timesteps"));
  if (s.train.session.checkpoint_every > 0)
    fail("{} does not apply to {} (each timestep's model is written as soon as it is done)",
         name("checkpoint_every"), name("timesteps"));
  const std::string& out = s.train.session.output;
  if (out.empty()) fail("{} needs {}: the directory of the per-timestep models", name("timesteps"), name("output"));
  const std::string ext = extension_of(out);
  if (ext == ".vnr" || ext == ".bson")
    fail("{} '{}' looks like a model file; with {} it names a directory (models go to DIR/t0000.vnr, ...)",
         name("output"), out, name("timesteps"));
  std::error_code ec;
  if (fs::exists(out, ec) && !fs::is_directory(out, ec))
    fail("{} '{}' is an existing file; with {} it names a directory for the per-timestep models", name("output"),
         out, name("timesteps"));
}

SeriesRunResult run_series(const SeriesRunSetup& s, const SeriesRunCallbacks& callbacks,
                           const std::function<std::string(const std::string&)>& name) {
  check_series_setup(s, name);
  const TrainingSetup& t = s.train;
  ModelConfig config = load_config(t.config);
  // The series and the selection, every selected timestep described (validated) before training.
  // (timestep 0 given explicitly: a plain raw file then counts the whole frames it holds)
  const auto raw_at = [&](int timestep) {
    RawOptions r = t.raw;
    r.timestep = timestep;
    return r;
  };
  const VolumeDesc desc0 = describe_volume(t.volume, raw_at(0));
  if (desc0.n_timesteps <= 1)
    fail("'{}' has a single timestep; --timesteps needs a time series (a 4-D sidecar, a sidecar whose \"file\" "
         "lists one file per timestep, or a scene with several dataSource entries)",
         t.volume);
  const std::vector<int> ts = parse_timestep_selection(s.timesteps, desc0.n_timesteps);
  for (int k : ts) describe_volume(t.volume, raw_at(k));
  const uint64_t frame_bytes = desc0.dims.count() * dtype_size(desc0.dtype);
  if (t.target_ratio > 0) {  // compact models of frame bytes / R, one per timestep (docs/COMPRESSION.md)
    std::string sizing;
    config = size_config_for_bytes(config, uint64_t(double(frame_bytes) / t.target_ratio), t.bits_per_param, &sizing);
    if (callbacks.note) callbacks.note(fmt::format("--target-ratio {:g}: {} (per timestep)", t.target_ratio, sizing));
  }
  if (callbacks.on_selection) callbacks.on_selection(desc0, ts);
  const std::string& dir = t.session.output;
  make_output_dir(dir);
  SeriesRun run{s, callbacks, create_model(config, desc0.dims, desc0.dtype, 0, 1, t.seed), ts};
  run.result.report_path = s.report.empty() ? join_path(dir, "series.json") : s.report;
  run.frame_bytes = frame_bytes;
  run.load = [&](int k) { return load_volume(describe_volume(t.volume, raw_at(k)), t.load); };
  run.result.report = {{"mode", s.continuous ? "continuous" : "per_timestep"},
                       {"volume", t.volume},
                       {"output_dir", dir},
                       {"timesteps", ts},
                       {"n_timesteps", desc0.n_timesteps},
                       {"batch", t.batch},
                       {"seed", t.seed},
                       {"threads", num_threads()},
                       {"volume_bytes", frame_bytes}};
  // Per timestep, each frame is copied to the GPU; continuously, the current frame's host sampler feeds it.
  const DeviceChoice device = choose_training_device(t.device, *run.model.net, desc0.dims, !s.continuous, t.batch);
  run.device = device.device;
  run.result.report["device"] = device_name(run.device);
  if (callbacks.note && !device.note.empty()) callbacks.note("note: " + device.note);
  if (callbacks.note && run.device == Device::Cuda) callbacks.note("training on " + cuda::devices().at(0).name);
  run.t_all = std::chrono::steady_clock::now();
  run.precision = resolve_training_precision(t.precision, *run.model.net);
  try {
    if (!s.continuous) train_per_timestep(run);
    else train_continuously(run);
  } catch (const Error& e) {
    if (run.saved == 0) throw;
    fail("{} ({} finished model{} kept in '{}', rows in '{}')", e.what(), run.saved, run.saved == 1 ? "" : "s", dir,
         run.result.report_path);
  }
  return std::move(run.result);
}

}  // namespace vnr
