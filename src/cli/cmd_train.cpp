// `vnr train VOLUME -o MODEL`: parses the options into a TrainingSetup, runs the library's
// TrainingSession and prints its progress and result (time series: cmd_train_series.cpp).
#include <atomic>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <optional>
#include "cli.h"
#include "train_cli.h"
#include "train_options.h"
#include "vnr/error.h"
#include "vnr/threads.h"
#include "vnr/progress.h"
#include "vnr/units.h"
#include "vnr/online.h"
#include "vnr/trainer.h"

namespace vnr::cli {

namespace {

// Ctrl-C or SIGTERM during training asks the session to stop after the current step; it still
// evaluates and saves the model (minutes of training are not thrown away). A second signal exits at
// once, leaving the previous model file intact.
std::atomic<TrainingSession*> g_session{nullptr};
extern "C" void on_stop_signal(int) {
  if (TrainingSession* s = g_session.load()) s->request_stop();
  handle_stop_signals(exit_on_signal);
}

struct SessionStopGuard {
  explicit SessionStopGuard(TrainingSession& s) {
    g_session.store(&s);  // before the handler can run
    signals.emplace(on_stop_signal);
  }
  ~SessionStopGuard() {
    signals.reset();
    g_session.store(nullptr);
  }
  std::optional<StopSignalScope> signals;
};

// The error bound's line (--max-error/--max-rel-error): the guarantee and what the residuals cost.
void print_error_bound(const Json& report) {
  if (!report.contains("error_bound")) return;
  const Json& b = report["error_bound"];
  const bool wavelet = b.value("transform", "none") != "none";
  std::printf("error bound %.4g (data units) %s; residuals: %.2f%% of %s non-zero, %s (%.3f bits/voxel), "
              "network %s\n",
              b["max_error"].get<double>(), b["holds"].get<bool>() ? "holds at every voxel" : "VIOLATED",
              100 * b["residual_nonzero_fraction"].get<double>(), wavelet ? "wavelet coefficients" : "voxels", human_bytes(b["residual_bytes"].get<double>()).c_str(),
              b["residual_bits_per_voxel"].get<double>(), human_bytes(b["network_bytes"].get<double>()).c_str());
  if (report.contains("network_psnr"))
    std::printf("the network alone (what renders and answers point queries): PSNR %.2f dB\n",
                report["network_psnr"].get<double>());
}

void print_result(const TrainArgs& a, const TrainingSession& session, const TrainingResult& r,
                  const TrainPreview* preview, const std::string& preview_dir) {
  std::printf("trained %lld steps in %.2fs (%.2f M samples/s%s), final loss %.6f\n", (long long)r.steps, r.seconds,
              r.samples_per_second / 1e6, r.report["precision"] == "bf16" ? ", bf16 MLP" : "", r.final_loss);
  if (preview)
    std::printf("previews: %lld PNG(s) in %s, %.2fs (not counted as training time)\n",
                (long long)preview->frames_written(), preview_dir.c_str(), session.side_seconds());
  std::printf("PSNR %.2f dB%s", r.psnr, r.evaluation_note.c_str());
  if (r.ssim) std::printf(", SSIM %.4f", *r.ssim);
  std::printf(", max |error| %.4g (%.4g in data units)\n", r.max_abs_error, r.max_abs_error_original);
  std::printf("model %s: %s, %llu parameters; volume %s; compression ratio %s\n", a.s.session.output.c_str(),
              human_bytes(double(r.model_bytes)).c_str(), (unsigned long long)r.report["n_params"].get<uint64_t>(),
              human_bytes(double(source_bytes(session.model()))).c_str(), format_ratio(r.compression_ratio).c_str());
  print_error_bound(r.report);
}

void run_train(const TrainArgs& a) {
  set_num_threads(a.threads);
  if (!a.timesteps.empty()) {
    if (a.preview.enabled()) fail("--preview-* options are not supported with --timesteps");
    return run_train_series(a);
  }
  if (!a.bricks.empty() || a.resume) return run_train_bricks(a);
  // Everything that can be checked without the data is checked first, so mistakes fail fast.
  TrainingSetup setup = setup_of(a, a.preview.enabled());
  if (a.eval_samples < 0) fail("--eval-samples must be non-negative, got {}", a.eval_samples);
  if (a.continuous || a.switch_every) fail("--continuous and --switch-every need --timesteps");
  check_training_setup(setup);
  const std::optional<PreviewOptions> preview_opts = a.preview.options();  // checks the flags, creates the dir
  auto say = [&](const std::string& line) {
    if (!a.quiet) std::fprintf(stderr, "%s\n", line.c_str());
  };
  const int64_t steps = planned_steps(a.s.steps, a.seconds);
  const bool by_time = steps < 0;
  std::optional<Progress> bar;
  std::optional<SessionStopGuard> guard;
  std::unique_ptr<TrainPreview> preview;
  // Before a session trains: the progress bar, Ctrl-C, and the previews.
  auto before_training = [&](TrainingSession& s) {
    guard.reset();
    guard.emplace(s);
    if (bar) bar->finish();  // the previous candidate's (--target-psnr)
    bar.emplace("train", by_time ? a.seconds : double(steps), a.quiet);
    s.add_step_callback([&bar, &s, by_time](const TrainingProgress& p) {
      std::string extra = fmt::format("step {} loss {:.5f} {:.2f} M samples/s", p.step, p.loss, p.samples_per_second / 1e6);
      if (const std::optional<double> wait = s.io_wait_seconds()) extra += fmt::format(" io wait {:.1f}s", *wait);
      bar->update(by_time ? p.elapsed : double(p.step), extra);
    });
    if (preview_opts) {
      preview = std::make_unique<TrainPreview>(*preview_opts, s, s.model().dims);
      s.add_side_work([&](const TrainingProgress& p) { preview->after_step(p.step); });
    }
  };
  if (preview_opts && setup.target_psnr > 0 && setup.target_ratio <= 0)
    fail("--preview-* options are not supported with --target-psnr alone (it trains several models)");
  TargetTraining trained;
  try {
    auto open = [&](const TrainingSetup& s) { return open_training_session(s, say); };
    trained = train_for_targets(setup, steps, a.seconds, open, say, before_training);
  } catch (const std::exception&) {
    if (bar) bar->finish();
    throw;
  }
  std::unique_ptr<TrainingSession>& session = trained.session;
  const std::optional<PsnrSearch>& search = trained.search;
  if (!trained.compact.is_null() && setup.target_psnr > 0 && trained.compact["heldback_psnr"].get<double>() < setup.target_psnr)
    say(fmt::format("warning: --target-psnr {}: this model reaches only {:.2f} dB on held-back samples; train "
                    "longer or with a larger model (a lower --target-ratio)",
                    setup.target_psnr, trained.compact["heldback_psnr"].get<double>()));
  guard.reset();
  if (preview) session->run_side_work([&] { preview->finish(session->steps_done()); });  // the final state
  bar->finish(fmt::format("({} steps, loss {:.5f})", session->steps_done(), session->last_loss()));
  if (session->stop_requested())
    std::fprintf(stderr, "interrupted after %lld steps: evaluating and saving the model (Ctrl-C again to abort)\n",
                 (long long)session->steps_done());
  TrainingResult r = session->finish({.ssim = !a.no_ssim, .eval_samples = a.eval_samples});
  if (search) {
    r.report["psnr_search"] = {{"target_psnr", setup.target_psnr}, {"reached", search->reached}, {"tried", search->tried}};
    std::printf("--target-psnr %g: %s after %zu model(s)\n", setup.target_psnr,
                search->reached ? "the smallest model that reaches it" : "NOT reached; the largest model",
                search->tried.size());
    if (search->reached && std::isfinite(r.psnr) && r.psnr < setup.target_psnr)
      std::fprintf(stderr, "note: the full evaluation gives %.2f dB, below the held-back estimate that chose this "
                           "model; a larger --target-psnr margin or more training closes the gap\n", r.psnr);
  }
  print_result(a, *session, r, preview.get(), preview_opts ? preview_opts->dir : std::string());
  r.report["setup"] = setup.to_json();  // what the run was given (TrainingSetup::from_json reads it back)
  write_report(a.report, r.report);
}

}  // namespace

void add_train(CLI::App& app) {
  auto a = std::make_shared<TrainArgs>();
  CLI::App* c = app.add_subcommand("train", "train a neural representation of a volume");
  c->add_option("volume", a->s.volume, "volume: JSON sidecar, instantvnr scene, .nrrd/.nhdr, FILE.h5:/DATASET, FILE.nc:VARIABLE, or raw (with --dims --dtype)")
      ->required();
  c->add_option("-o,--output", a->s.session.output, "model file (.vnr; .json/.bson writes instantvnr's BSON)")->required();
  add_training_options(c, *a);
  c->add_option("--eval-samples", a->eval_samples,
                "when the volume is not in memory: random voxels of the final PSNR estimate (0: no evaluation)")
      ->capture_default_str();
  c->add_option("--checkpoint-every", a->s.session.checkpoint_every,
                "write the model (atomically) every N steps while training, not only at the end");
  c->add_option("--timesteps", a->timesteps,
                 "train a time series: all, A-B or A,B,C; one model per timestep in the -o directory, each "
                 "warm-started from the previous one");
  c->add_flag("--continuous", a->continuous,
              "with --timesteps: keep training one network while the target timestep advances every "
              "--switch-every steps (fixed learning rate), reporting the steps PSNR takes to recover");
  c->add_option("--switch-every", a->switch_every, "with --continuous: training steps per timestep");
  c->add_flag("--no-ssim", a->no_ssim, "skip the 3-D SSIM of the final evaluation");
  a->preview.add(c);
  c->callback([a]() { run_train(*a); });
}

}  // namespace vnr::cli
