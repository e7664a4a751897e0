// `vnr train SERIES --timesteps all|A-B|A,B,C -o DIR [--continuous --switch-every N]`: time-varying
// volumes, trained by the library's run_series (vnr/series.h: the models, the report and what
// a failure keeps); here the options, Ctrl-C, the progress bars and the tables.
#include <fmt/format.h>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <memory>
#include <optional>
#include "cli.h"
#include "train_cli.h"
#include "vnr/progress.h"
#include "vnr/trainer.h"

namespace vnr::cli {
namespace {

// Ctrl-C or SIGTERM stops after the current step; that timestep (window) is still evaluated and
// saved, and the series ends there. A second signal exits at once.
volatile std::sig_atomic_t g_series_interrupted = 0;
extern "C" void on_stop_signal_series(int) {
  g_series_interrupted = 1;
  handle_stop_signals(exit_on_signal);
}

struct SeriesStopGuard {
  SeriesStopGuard() {
    g_series_interrupted = 0;
    signals.emplace(on_stop_signal_series);
  }
  std::optional<StopSignalScope> signals;
};

SeriesRunSetup series_setup_of(const TrainArgs& a) {
  SeriesRunSetup s;
  s.train = setup_of(a, false);
  s.seconds = a.seconds;
  s.timesteps = a.timesteps;
  s.continuous = a.continuous;
  s.switch_every = a.switch_every;
  s.report = a.report;
  s.ssim = !a.no_ssim;
  return s;
}

// The continuous run's tables: per timestep, and per switch with its recovery.
void print_continuous(const SeriesRunResult& run, int64_t switch_every, int64_t global) {
  const ContinuousResult& res = *run.continuous;
  std::printf("continuous training: %lld steps, %lld per timestep, learning rate fixed at %g; PSNR probe: %lld "
              "voxels every %lld steps\n",
              (long long)global, (long long)switch_every, double(res.learning_rate), (long long)res.probe_voxels,
              (long long)run.continuous_options.probe_every);
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

}  // namespace

void run_train_series(const TrainArgs& a) {
  const SeriesRunSetup s = series_setup_of(a);
  SeriesRunCallbacks cb;
  cb.hooks.stop = [] { return g_series_interrupted != 0; };
  cb.note = [&](const std::string& line) {
    if (!a.quiet) std::fprintf(stderr, "%s\n", line.c_str());
  };
  std::unique_ptr<Progress> bar;
  const bool by_time = a.seconds > 0 && a.s.steps < 0;
  int64_t global = 0;  // continuous: steps of the run
  auto t_start = std::chrono::steady_clock::now();
  cb.on_selection = [&](const VolumeDesc& d, const std::vector<int>& ts) {
    if (!a.quiet)
      std::fprintf(stderr, "series %s: %lldx%lldx%lld %s x %d timesteps; training %zu (%s)%s\n", a.s.volume.c_str(),
                   (long long)d.dims.x, (long long)d.dims.y, (long long)d.dims.z, dtype_name(d.dtype), d.n_timesteps,
                   ts.size(), a.timesteps.c_str(),
                   a.continuous ? fmt::format(", continuously, {} steps each", a.switch_every).c_str() : "");
    if (a.continuous)
      bar = std::make_unique<Progress>("train", double(a.switch_every) * double(ts.size()), a.quiet);
    else
      std::printf("timestep  start  steps  seconds  final loss  PSNR (dB)%s  model\n", a.no_ssim ? "" : "   SSIM");
  };
  if (!a.continuous) {
    const int64_t steps = planned_steps(a.s.steps, a.seconds);
    cb.hooks.on_loaded = [&](int t, double) {
      bar = std::make_unique<Progress>(fmt::format("t{:04d}", t), by_time ? a.seconds : double(steps), a.quiet);
      t_start = std::chrono::steady_clock::now();
    };
    cb.hooks.on_step = [&](int, int64_t step, float loss) {
      bar->update(by_time ? seconds_since(t_start) : double(step), fmt::format("step {} loss {:.5f}", step, loss));
    };
    cb.on_row = [&](const Json& row) {
      bar->finish(fmt::format("({} steps, loss {:.5f})", row["steps"].get<int64_t>(), row["final_loss"].get<double>()));
      std::printf("t%04d     %-5s  %5lld  %7.2f  %10.6f  %9.2f%s  %s\n", row["timestep"].get<int>(),
                  row["warm_start"].get<bool>() ? "warm" : "init", (long long)row["steps"].get<int64_t>(),
                  row["seconds"].get<double>(), row["final_loss"].get<double>(), row["psnr"].get<double>(),
                  a.no_ssim ? "" : fmt::format("  {:.4f}", row["ssim"].get<double>()).c_str(),
                  row["model"].get<std::string>().c_str());
      std::fflush(stdout);
    };
  } else {
    cb.hooks.on_step = [&](int t, int64_t, float loss) {
      ++global;
      bar->update(double(global), fmt::format("timestep {} step {} loss {:.5f}", t, global, loss));
    };
  }
  SeriesRunResult run;
  {
    SeriesStopGuard guard;
    run = run_series(s, cb);
  }
  if (a.continuous) {
    const std::vector<float>& losses = run.continuous->loss_history;
    if (bar) bar->finish(fmt::format("({} steps, loss {:.5f})", global, losses.empty() ? 0.f : losses.back()));
  }
  if (run.interrupted) {
    const int last = run.report["rows"].back()["timestep"].get<int>();
    if (a.continuous)
      std::fprintf(stderr, "interrupted in timestep %d: its model is saved; later timesteps were not trained\n", last);
    else
      std::fprintf(stderr, "interrupted: stopped after timestep %d (its model is saved; later timesteps were not trained)\n",
                   last);
  }
  if (a.continuous) print_continuous(run, a.switch_every, global);
  const size_t n = run.report.contains("rows") ? run.report["rows"].size() : 0;
  std::printf("%zu model%s in %s, report %s\n", n, n == 1 ? "" : "s", a.s.session.output.c_str(), run.report_path.c_str());
}

}  // namespace vnr::cli
