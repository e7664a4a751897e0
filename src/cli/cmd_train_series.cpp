// `vnr train SERIES --timesteps all|A-B|A,B,C -o DIR [--continuous --switch-every N]`: time-varying
// volumes (paper appendix "Adaptivity with Time-Varying Data"); the training itself is
// vnr/train/series.h. Models go to DIR/t0000.vnr, DIR/t0001.vnr, ... (the series' timestep index,
// zero-padded to 4 digits), each written atomically as soon as its timestep is done, and the report
// (DIR/series.json unless --report) is rewritten after every timestep, so a failure or Ctrl-C
// later leaves every finished model and its row on disk.
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <system_error>
#include "cli.h"
#include "train_cli.h"
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/threads.h"
#include "vnr/progress.h"
#include "vnr/nn/config.h"
#include "vnr/train/make_trainer.h"
#include "vnr/train/model_io.h"
#include "vnr/train/series.h"
#include "vnr/train/session.h"

namespace vnr::cli {
namespace {

namespace fs = std::filesystem;

// Ctrl-C or SIGTERM stops after the current step; that timestep (window) is still evaluated and
// saved, and the series ends there. A second signal exits at once.
volatile std::sig_atomic_t g_series_interrupted = 0;
extern "C" void on_stop_signal_series(int) {
  g_series_interrupted = 1;
  handle_stop_signals(exit_on_signal);
}

struct StopSignalGuard {
  StopSignalGuard() {
    g_series_interrupted = 0;
    signals.emplace(on_stop_signal_series);
  }
  std::optional<StopSignalScope> signals;
};

void check_series_args(const TrainArgs& a) {
  TrainingSetup shared;  // --batch, --steps and --macrocell-size: checked as for one volume
  shared.batch = a.batch;
  shared.steps = a.steps;
  shared.macrocell_size = a.macrocell_size;
  check_training_setup(shared);
  if (a.seconds < 0) fail("--seconds must not be negative, got {}", a.seconds);
  if (a.vol.timestep >= 0)
    fail("--timestep picks one timestep of a single-volume run; with --timesteps give the selection there "
         "(e.g. --timesteps {})",
         a.vol.timestep);
  if (a.continuous) {
    if (a.switch_every <= 0)
      fail("--continuous needs --switch-every N (training steps per timestep, N > 0), got {}", a.switch_every);
    if (a.steps >= 0 || a.seconds > 0)
      fail("--continuous trains --switch-every steps per timestep; --steps and --seconds do not apply");
    if (a.target_ratio > 0 || a.max_error > 0 || a.max_rel_error > 0)
      fail("--target-ratio, --max-error and --max-rel-error make per-timestep models; not with --continuous");
  } else if (a.switch_every != 0) {
    fail("--switch-every needs --continuous");
  }
  if (!a.sampler.empty() && a.sampler != "incore")
    fail("--sampler {} is not supported with --timesteps (each timestep is trained in memory)", a.sampler);
  if (a.checkpoint_every > 0)
    fail("--checkpoint-every does not apply to --timesteps (each timestep's model is written as soon as it is done)");
  const std::string ext = extension_of(a.output);
  if (ext == ".vnr" || ext == ".bson")
    fail("-o '{}' looks like a model file; with --timesteps -o names a directory (models go to DIR/t0000.vnr, ...)",
         a.output);
  std::error_code ec;
  if (fs::exists(a.output, ec) && !fs::is_directory(a.output, ec))
    fail("-o '{}' is an existing file; with --timesteps -o names a directory for the per-timestep models",
         a.output);
}

void make_output_dir(const std::string& dir) {
  std::error_code ec;
  if (fs::is_directory(dir, ec)) return;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir)) fail("cannot create output directory '{}': {}", dir, ec ? ec.message() : "unknown error");
}

// One `vnr train --timesteps` run: what both modes share.
struct SeriesRun {
  SeriesRun(const TrainArgs& args, Model m, std::vector<int> timesteps)
      : a(args), model(std::move(m)), ts(std::move(timesteps)) {}
  const TrainArgs& a;
  Model model;
  std::vector<int> ts;
  FrameLoader load;
  SeriesHooks hooks;
  Json report;
  std::string report_path;
  uint64_t frame_bytes = 0;
  Precision precision = Precision::FP32;
  Device device = Device::Cpu;
  std::chrono::steady_clock::time_point t_all;
  std::unique_ptr<Progress> bar;
  int saved = 0;

  TrainOptions train_options() const {
    TrainOptions t{a.batch, a.seed};
    t.precision = precision;
    return t;
  }
  // Saves the model of r's timestep (a TimestepResult or a WindowResult) and returns its report row
  // with the keys both modes share.
  template <class Result>
  Json save(const Model& m, const Result& r) {
    const std::string path = join_path(a.output, timestep_model_name(r.timestep));
    save_model(path, m);
    ++saved;
    const uint64_t bytes = file_size(path);
    Json row = {{"timestep", r.timestep},
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
                {"ssim", a.no_ssim ? Json(nullptr) : Json(r.eval.ssim)},
                {"max_abs_error", r.eval.max_abs_error},
                {"max_abs_error_original", r.eval.max_abs_error_original}};
    return row;
  }
  // Appends a row and rewrites the report, marked incomplete until finish().
  void add_row(Json row) {
    report["rows"].push_back(std::move(row));  // one per saved model
    report["complete"] = false;
    write_report(report_path, report);
  }
  void finish(bool interrupted) {
    report["interrupted"] = interrupted;
    report["complete"] = !interrupted;
    report["total_seconds"] = seconds_since(t_all);
    write_report(report_path, report);
  }
  void print_models_line() const {
    const size_t n = report.contains("rows") ? report["rows"].size() : 0;
    std::printf("%zu model%s in %s, report %s\n", n, n == 1 ? "" : "s", a.output.c_str(),
                report_path.c_str());
  }
};

// One model per timestep, warm-started (train_series: a TrainingSession per timestep).
void train_per_timestep(SeriesRun& run) {
  const TrainArgs& a = run.a;
  const bool by_time = a.seconds > 0 && a.steps < 0;
  SeriesOptions so;
  so.train = run.train_options();
  so.device = run.device;
  so.mlp = cuda::parse_mlp_path(run.a.mlp);
  so.steps = planned_steps(a.steps, a.seconds);
  so.cooldown = a.cooldown;
  so.seconds = a.seconds;
  so.macrocell_size = a.macrocell_size;
  so.ssim = !a.no_ssim;
  if (a.target_ratio > 0) so.compact.target_bytes = uint64_t(double(run.frame_bytes) / a.target_ratio);
  so.error_bound = {a.max_error, a.max_rel_error};
  run.report["steps_per_timestep"] = so.steps >= 0 ? Json(so.steps) : Json(nullptr);
  run.report["seconds_per_timestep"] = a.seconds;
  run.report["config"] = run.model.net->config_json();
  run.report["precision"] = precision_name(run.precision);
  auto t_start = std::chrono::steady_clock::now();
  run.hooks.on_loaded = [&](int t, double) {
    run.bar = std::make_unique<Progress>(fmt::format("t{:04d}", t), by_time ? a.seconds : double(so.steps), a.quiet);
    t_start = std::chrono::steady_clock::now();
  };
  run.hooks.on_step = [&](int, int64_t s, float loss) {
    run.bar->update(by_time ? seconds_since(t_start) : double(s), fmt::format("step {} loss {:.5f}", s, loss));
  };
  std::printf("timestep  start  steps  seconds  final loss  PSNR (dB)%s  model\n", a.no_ssim ? "" : "   SSIM");
  auto done = [&](const TimestepResult& r, const Model& m) {
    run.bar->finish(fmt::format("({} steps, loss {:.5f})", r.steps, r.final_loss));
    Json row = run.save(m, r);
    row["warm_start"] = r.warm_started;
    if (!r.compact.is_null()) row["compact"] = r.compact;
    if (!r.error_bound.is_null()) {
      row["error_bound"] = r.error_bound;
      row["error_bound"]["holds"] = r.eval.max_abs_error_original <= r.error_bound["max_error"].get<double>();
    }
    const std::string path = row["model"].get<std::string>();
    run.add_row(std::move(row));
    std::printf("t%04d     %-5s  %5lld  %7.2f  %10.6f  %9.2f%s  %s\n", r.timestep, r.warm_started ? "warm" : "init",
                (long long)r.steps, r.seconds, r.final_loss, r.eval.psnr,
                a.no_ssim ? "" : fmt::format("  {:.4f}", r.eval.ssim).c_str(), path.c_str());
    std::fflush(stdout);
  };
  std::vector<TimestepResult> res = train_series(run.model, run.ts, run.load, so, run.hooks, done);
  const bool interrupted = !res.empty() && res.back().interrupted;
  run.finish(interrupted);
  if (interrupted)
    std::fprintf(stderr, "interrupted: stopped after timestep %d (its model is saved; later timesteps were not trained)\n",
                 res.back().timestep);
  run.print_models_line();
}

// The continuous run's tables: per timestep, and per switch with its recovery.
void print_continuous(const SeriesRun& run, const ContinuousResult& res, const ContinuousOptions& co, int64_t global) {
  std::printf("continuous training: %lld steps, %lld per timestep, learning rate fixed at %g; PSNR probe: %lld "
              "voxels every %lld steps\n",
              (long long)global, (long long)run.a.switch_every, double(res.learning_rate), (long long)res.probe_voxels,
              (long long)co.probe_every);
  std::printf("timestep  steps  seconds  PSNR (dB)  model\n");
  for (size_t i = 0; i < res.windows.size(); ++i)
    std::printf("t%04d     %5lld  %7.2f  %9.2f  %s\n", res.windows[i].timestep, (long long)res.windows[i].steps,
                res.windows[i].seconds, res.windows[i].eval.psnr, run.report["rows"][i]["model"].get<std::string>().c_str());
  if (res.windows.size() > 1) {
    std::printf("switch          PSNR before  PSNR after  recovered after\n");
    for (const WindowResult& w : res.windows) {
      if (!w.has_switch) continue;
      std::string rec = w.recovery_steps >= 0
                            ? fmt::format("{} steps ({:.2f} s)", w.recovery_steps, w.recovery_seconds)
                            : fmt::format("not recovered within {} steps", w.steps);
      std::printf("t%04d -> t%04d  %8.2f dB  %7.2f dB  %s\n", w.from_timestep, w.timestep, w.psnr_before,
                  w.psnr_after, rec.c_str());
    }
  }
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
  const TrainArgs& a = run.a;
  ContinuousOptions co;
  co.train = run.train_options();
  co.device = run.device;
  co.mlp = cuda::parse_mlp_path(run.a.mlp);
  co.switch_every = a.switch_every;
  co.macrocell_size = a.macrocell_size;
  co.ssim = !a.no_ssim;
  run.bar = std::make_unique<Progress>("train", double(a.switch_every) * double(run.ts.size()), a.quiet);
  int64_t global = 0;
  run.hooks.on_step = [&](int t, int64_t, float loss) {
    ++global;
    run.bar->update(double(global), fmt::format("timestep {} step {} loss {:.5f}", t, global, loss));
  };
  auto done = [&](const WindowResult& w, const Model& m) {
    Json row = run.save(m, w);
    row["first_step"] = w.first_step;
    row["probe_psnr_end"] = w.psnr_end;
    row["switch"] = switch_json(w);
    run.report["switch_every"] = a.switch_every;
    run.report["learning_rate"] = m.net->config().adam.learning_rate;
    run.report["config"] = m.net->config_json();
    run.report["precision"] = precision_name(run.precision);
    run.add_row(std::move(row));
  };
  ContinuousResult res = train_continuous(run.model, run.ts, run.load, co, run.hooks, done);
  const bool interrupted = !res.windows.empty() && res.windows.back().interrupted;
  run.bar->finish(
      fmt::format("({} steps, loss {:.5f})", global, res.loss_history.empty() ? 0.f : res.loss_history.back()));
  Json probes = Json::array();
  for (const ProbePoint& p : res.probes) probes.push_back({p.step, p.timestep, p.psnr});
  run.report["probe_voxels"] = res.probe_voxels;
  run.report["probe_every"] = co.probe_every;
  run.report["recovery_tolerance_db"] = co.recovery_tolerance_db;
  run.report["probes"] = probes;
  run.report["loss_history"] = res.loss_history;
  run.finish(interrupted);
  if (interrupted)
    std::fprintf(stderr, "interrupted in timestep %d: its model is saved; later timesteps were not trained\n",
                 res.windows.back().timestep);
  print_continuous(run, res, co, global);
  run.print_models_line();
}

}  // namespace

void run_train_series(const TrainArgs& a) {
  check_series_args(a);
  ModelConfig config = load_config(a.config);
  const RawOptions raw = a.vol.raw();
  const LoadOptions load_opts = a.vol.load();

  // The series and the selection, every selected timestep described (validated) before training.
  // (timestep 0 given explicitly: a plain raw file then counts the whole frames it holds)
  const VolumeDesc desc0 = describe_volume(a.volume, [&] {
    RawOptions r = raw;
    r.timestep = 0;
    return r;
  }());
  if (desc0.n_timesteps <= 1)
    fail("'{}' has a single timestep; --timesteps needs a time series (a 4-D sidecar, a sidecar whose \"file\" "
         "lists one file per timestep, or a scene with several dataSource entries)",
         a.volume);
  const std::vector<int> ts = parse_timestep_selection(a.timesteps, desc0.n_timesteps);
  for (int t : ts) {
    RawOptions r = raw;
    r.timestep = t;
    describe_volume(a.volume, r);
  }
  const uint64_t frame_bytes = desc0.dims.count() * dtype_size(desc0.dtype);
  if (a.target_ratio > 0) {  // compact models of frame bytes / R, one per timestep (docs/COMPRESSION.md)
    std::string note;
    config = size_config_for_bytes(config, uint64_t(double(frame_bytes) / a.target_ratio), a.bits_per_param, &note);
    if (!a.quiet) std::fprintf(stderr, "--target-ratio %g: %s (per timestep)\n", a.target_ratio, note.c_str());
  }
  make_output_dir(a.output);
  const std::string report_path = a.report.empty() ? join_path(a.output, "series.json") : a.report;
  if (!a.quiet)
    std::fprintf(stderr, "series %s: %lldx%lldx%lld %s x %d timesteps; training %zu (%s)%s\n", a.volume.c_str(),
                 (long long)desc0.dims.x, (long long)desc0.dims.y, (long long)desc0.dims.z, dtype_name(desc0.dtype),
                 desc0.n_timesteps, ts.size(), a.timesteps.c_str(),
                 a.continuous ? fmt::format(", continuously, {} steps each", a.switch_every).c_str() : "");

  SeriesRun run{a, create_model(config, desc0.dims, desc0.dtype, 0, 1, a.seed), ts};
  run.report_path = report_path;
  run.frame_bytes = frame_bytes;
  run.load = [&](int t) {
    RawOptions r = raw;
    r.timestep = t;
    return load_volume(describe_volume(a.volume, r), load_opts);
  };
  run.hooks.stop = [] { return g_series_interrupted != 0; };
  run.report = {{"mode", a.continuous ? "continuous" : "per_timestep"},
                {"volume", a.volume},
                {"output_dir", a.output},
                {"timesteps", ts},
                {"n_timesteps", desc0.n_timesteps},
                {"batch", a.batch},
                {"seed", a.seed},
                {"threads", num_threads()},
                {"volume_bytes", frame_bytes}};
  // Per timestep, each frame is copied to the GPU; continuously, the current frame's host sampler feeds it.
  const DeviceChoice device = choose_training_device(a.device, *run.model.net, desc0.dims, !a.continuous, a.batch);
  run.device = device.device;
  run.report["device"] = device_name(run.device);
  if (!a.quiet && !device.note.empty()) std::fprintf(stderr, "note: %s\n", device.note.c_str());
  if (!a.quiet && run.device == Device::Cuda)
    std::fprintf(stderr, "training on %s\n", cuda::devices().at(0).name.c_str());
  run.t_all = std::chrono::steady_clock::now();
  run.precision = resolve_training_precision(a.precision, *run.model.net);
  try {
    StopSignalGuard guard;
    if (!a.continuous)
      train_per_timestep(run);
    else
      train_continuously(run);
  } catch (const Error& e) {
    if (run.saved == 0) throw;
    fail("{} ({} finished model{} kept in '{}', rows in '{}')", e.what(), run.saved, run.saved == 1 ? "" : "s",
         a.output, report_path);
  }
}

}  // namespace vnr::cli
