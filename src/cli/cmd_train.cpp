#include <chrono>
#include <csignal>
#include <cmath>
#include <cstdio>
#include "cli.h"
#include "vnr/core/error.h"
#include "vnr/core/fileio.h"
#include "vnr/core/parallel.h"
#include "vnr/core/progress.h"
#include "vnr/nn/config.h"
#include "vnr/train/model_io.h"
#include "vnr/train/trainer.h"

namespace vnr::cli {

namespace {

// Ctrl-C during training stops after the current step and still evaluates and saves the model
// (minutes of training are not thrown away); a second Ctrl-C exits at once.
volatile std::sig_atomic_t g_interrupted = 0;
extern "C" void on_sigint(int) {
  g_interrupted = 1;
  std::signal(SIGINT, SIG_DFL);
}

struct TrainArgs {
  std::string volume, output, config = "paper", report;
  double target_ratio = 0, seconds = 0;
  int64_t steps = -1, batch = 65536;
  uint32_t seed = 1337;
  int threads = 0;
  int macrocell_size = 16;
  bool quiet = false, no_ssim = false;
  VolumeArgs vol;
};

void run_train(const TrainArgs& a) {
  set_num_threads(a.threads);
  // Everything that can be checked without the data is checked first, so mistakes fail fast.
  if (a.batch <= 0 || a.batch % kChunk != 0) fail("--batch must be a positive multiple of {}, got {}", kChunk, a.batch);
  if (a.steps < -1) fail("--steps must be non-negative, got {}", a.steps);
  if (a.macrocell_size < 0) fail("--macrocell-size must be 0 (none) or positive, got {}", a.macrocell_size);
  Json config = load_config(a.config);
  VolumeDesc desc = describe_volume(a.volume, a.vol.raw());
  auto t_load = std::chrono::steady_clock::now();
  Volume vol = load_volume(desc, a.vol.load());
  if (!a.quiet)
    std::fprintf(stderr, "volume %s: %lldx%lldx%lld %s, %s, range [%g, %g], loaded in %.1fs\n", a.volume.c_str(),
                 (long long)vol.dims.x, (long long)vol.dims.y, (long long)vol.dims.z, dtype_name(vol.source_dtype),
                 human_bytes(double(vol.source_bytes())).c_str(), vol.lo, vol.hi, seconds_since(t_load));
  if (vol.hi == vol.lo && !a.quiet)
    std::fprintf(stderr, "note: the volume is constant (%g); it is represented as normalised 0\n", vol.lo);

  if (a.target_ratio > 0) {
    std::string note;
    config = size_config_for_ratio(config, vol.source_bytes(), a.target_ratio, &note);
    if (!a.quiet) std::fprintf(stderr, "%s\n", note.c_str());
  }
  Model model;
  model.net = std::make_unique<Network>(config);
  model.dims = vol.dims;
  model.source_dtype = vol.source_dtype;
  model.lo = vol.lo;
  model.hi = vol.hi;
  Network& net = *model.net;
  if (!a.quiet && a.target_ratio <= 0 && model.param_bytes() > vol.source_bytes())
    std::fprintf(stderr, "note: the model (%s) is larger than the volume (%s); use --target-ratio R to compress\n",
                 human_bytes(double(model.param_bytes())).c_str(), human_bytes(double(vol.source_bytes())).c_str());
  net.init_params(a.seed);

  const int64_t steps = a.steps >= 0 ? a.steps : (a.seconds > 0 ? INT64_MAX : 1000);
  Trainer trainer(net, std::make_shared<InCoreSampler>(vol), TrainOptions{a.batch, a.seed});
  if (a.macrocell_size > 0) trainer.enable_online_ranges(vol.dims, a.macrocell_size);
  const bool by_time = a.seconds > 0 && a.steps < 0;
  Progress bar("train", by_time ? a.seconds : double(steps), a.quiet);
  auto t0 = std::chrono::steady_clock::now();
  float loss = 0;
  int64_t done = 0;
  g_interrupted = 0;
  auto previous = std::signal(SIGINT, on_sigint);
  while (done < steps && !g_interrupted) {
    loss = trainer.step();
    ++done;
    double el = seconds_since(t0);
    if (!std::isfinite(loss)) fail("training diverged at step {} (loss {}); try a smaller learning rate", done, loss);
    bar.update(by_time ? el : double(done),
               fmt::format("step {} loss {:.5f} {:.2f} M samples/s", done, loss, double(done) * a.batch / el / 1e6));
    if (a.seconds > 0 && el >= a.seconds) break;
  }
  const double train_seconds = seconds_since(t0);
  std::signal(SIGINT, previous == SIG_ERR ? SIG_DFL : previous);
  bar.finish(fmt::format("({} steps, loss {:.5f})", done, loss));
  if (g_interrupted)
    std::fprintf(stderr, "interrupted after %lld steps: evaluating and saving the model (Ctrl-C again to abort)\n",
                 (long long)done);

  EvalResult ev = evaluate(net, vol, !a.no_ssim);
  model.training = {{"steps", done}, {"seconds", train_seconds}, {"interrupted", bool(g_interrupted)}, {"batch", a.batch}, {"seed", a.seed},
                    {"final_loss", loss}, {"psnr", ev.psnr}, {"threads", num_threads()}};
  if (!a.no_ssim) model.training["ssim"] = ev.ssim;
  if (trainer.has_online_ranges()) model.macrocells = trainer.online_ranges();
  save_model(a.output, model);
  const uint64_t model_bytes = file_size(a.output);
  const double ratio = double(vol.source_bytes()) / double(model_bytes);
  const double sps = double(done) * a.batch / train_seconds;
  std::printf("trained %lld steps in %.2fs (%.2f M samples/s), final loss %.6f\n", (long long)done, train_seconds,
              sps / 1e6, loss);
  std::printf("PSNR %.2f dB", ev.psnr);
  if (!a.no_ssim) std::printf(", SSIM %.4f", ev.ssim);
  std::printf(", max |error| %.4g (%.4g in data units)\n", ev.max_abs_error, ev.max_abs_error_original);
  std::printf("model %s: %s, %llu parameters; volume %s; compression ratio %.2f\n", a.output.c_str(),
              human_bytes(double(model_bytes)).c_str(), (unsigned long long)net.n_params(),
              human_bytes(double(vol.source_bytes())).c_str(), ratio);
  Json report = {{"steps", done},
                 {"seconds", train_seconds},
                 {"samples_per_second", sps},
                 {"final_loss", loss},
                 {"psnr", ev.psnr},
                 {"ssim", a.no_ssim ? Json(nullptr) : Json(ev.ssim)},
                 {"max_abs_error", ev.max_abs_error},
                 {"n_params", net.n_params()},
                 {"model_bytes", model_bytes},
                 {"volume_bytes", vol.source_bytes()},
                 {"compression_ratio", ratio},
                 {"batch", a.batch},
                 {"threads", num_threads()},
                 {"loss_history", trainer.loss_history()},
                 {"config", net.config_json()}};
  write_report(a.report, report);
}

}  // namespace

void add_train(CLI::App& app) {
  auto a = std::make_shared<TrainArgs>();
  CLI::App* c = app.add_subcommand("train", "train a neural representation of a volume");
  c->add_option("volume", a->volume, "volume: JSON sidecar, instantvnr scene, .nrrd/.nhdr, or raw (with --dims --dtype)")
      ->required();
  c->add_option("-o,--output", a->output, "model file (.vnr; .json/.bson writes instantvnr's BSON)")->required();
  c->add_option("--config", a->config, "preset (paper, small) or tiny-cuda-nn JSON config file")->capture_default_str();
  c->add_option("--target-ratio", a->target_ratio, "size the hash table so the model is about 1/R of the volume");
  c->add_option("--steps", a->steps, "training steps (default 1000, or unlimited with --seconds)");
  c->add_option("--seconds", a->seconds, "stop after this many seconds of training");
  c->add_option("--batch", a->batch, "samples per step (multiple of 256)")->capture_default_str();
  c->add_option("--seed", a->seed, "seed for initialisation and sampling")->capture_default_str();
  c->add_option("--threads", a->threads, "CPU threads (default: all cores)");
  c->add_option("--report", a->report, "write a JSON report");
  c->add_option("--macrocell-size", a->macrocell_size,
                 "voxels per macro-cell of the value ranges recorded from the training samples for rendering (0: none)")
      ->capture_default_str();
  c->add_flag("--no-ssim", a->no_ssim, "skip the 3-D SSIM of the final evaluation");
  c->add_flag("-q,--quiet", a->quiet, "no progress output");
  a->vol.add(c);
  c->callback([a]() { run_train(*a); });
}

}  // namespace vnr::cli
