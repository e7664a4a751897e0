#include <algorithm>
#include <chrono>
#include <csignal>
#include <cmath>
#include <cstdio>
#include <optional>
#include "cli.h"
#include "train_cli.h"
#include "vnr/core/error.h"
#include "vnr/core/fileio.h"
#include "vnr/core/parallel.h"
#include "vnr/core/progress.h"
#include "vnr/core/units.h"
#include "vnr/nn/config.h"
#include "vnr/online/preview.h"
#include "vnr/train/model_io.h"
#include "vnr/train/streaming_samplers.h"
#include "vnr/cuda/cuda.h"
#include "vnr/train/trainer.h"
#include "vnr/volume/raw_access.h"
#include "vnr/volume/stream.h"

namespace vnr::cli {

namespace {

// Ctrl-C during training stops after the current step and still evaluates and saves the model
// (minutes of training are not thrown away); a second Ctrl-C exits at once.
volatile std::sig_atomic_t g_interrupted = 0;
extern "C" void on_sigint(int) {
  g_interrupted = 1;
  std::signal(SIGINT, SIG_DFL);
}

// Where the training samples come from, and the volume when it is in memory.
struct TrainingData {
  std::string kind;  // incore | outofcore | mmap
  std::shared_ptr<Sampler> sampler;
  std::optional<Volume> vol;                       // incore only
  std::shared_ptr<OutOfCoreSampler> out_of_core;   // outofcore only
  std::shared_ptr<const RawVolumeFile> raw_file;   // outofcore only
  Int3 dims;
  DType dtype = DType::Float32;
  double lo = 0, hi = 1;
  uint64_t source_bytes() const { return dims.count() * dtype_size(dtype); }
};

TrainingData open_training_data(const TrainArgs& a, const VolumeDesc& desc, uint64_t budget) {
  TrainingData t;
  t.dims = desc.dims;
  t.dtype = desc.dtype;
  const uint64_t in_core_bytes = desc.dims.count() * sizeof(float);
  t.kind = a.sampler.empty() ? (in_core_bytes <= budget ? "incore" : "outofcore") : a.sampler;
  if (t.kind != "outofcore" && (a.blocks > 0 || a.refresh > 0 || !a.block_dims.empty() || a.grid_lr_scale != "1"))
    fail("--blocks, --refresh, --block-dims and --grid-lr-scale apply to --sampler outofcore (this run samples {})", t.kind);
  auto t0 = std::chrono::steady_clock::now();
  if (t.kind == "incore") {
    if (in_core_bytes > budget)
      fail("the volume needs {} in memory, more than the memory budget of {}; use --sampler outofcore (or mmap), or "
           "raise --memory-budget",
           human_bytes(double(in_core_bytes)), human_bytes(double(budget)));
    t.vol = load_volume(desc, a.vol.load());
    t.lo = t.vol->lo;
    t.hi = t.vol->hi;
    t.sampler = std::make_shared<InCoreSampler>(*t.vol);
    if (!a.quiet)
      std::fprintf(stderr, "volume %s: %lldx%lldx%lld %s, %s, range [%g, %g], loaded in %.1fs\n", a.volume.c_str(),
                   (long long)t.dims.x, (long long)t.dims.y, (long long)t.dims.z, dtype_name(t.dtype),
                   human_bytes(double(t.source_bytes())).c_str(), t.lo, t.hi, seconds_since(t0));
    return t;
  }
  if (t.kind != "outofcore" && t.kind != "mmap") fail("unknown --sampler '{}' (allowed: incore, outofcore, mmap)", t.kind);
  // Before any pass over the data: these samplers read at random offsets.
  require_random_access(desc, "--sampler " + t.kind);
  // The value range: the descriptor's, or one streaming pass (the volume is never loaded).
  const bool known_range = desc.range_lo && desc.range_hi;
  Progress scan_bar("value range", 1.0, a.quiet || known_range);
  ValueRange r = scan_value_range(desc, a.vol.load(), [&](double f) { scan_bar.update(f); });
  scan_bar.finish();
  t.lo = r.lo;
  t.hi = r.hi;
  if (!a.quiet)
    std::fprintf(stderr, "volume %s: %lldx%lldx%lld %s, %s, range [%g, %g]%s; sampled %s\n", a.volume.c_str(),
                 (long long)t.dims.x, (long long)t.dims.y, (long long)t.dims.z, dtype_name(t.dtype),
                 human_bytes(double(t.source_bytes())).c_str(), t.lo, t.hi,
                 known_range ? " (from the descriptor)" : fmt::format(" (scanned in {:.1f}s)", seconds_since(t0)).c_str(),
                 t.kind == "mmap" ? "through a memory map" : "out of core");
  if (t.kind == "mmap") {
    t.sampler = std::make_shared<MmapSampler>(std::make_shared<MappedVolume>(desc, t.lo, t.hi, a.vol.load().non_finite));
    return t;
  }
  t.raw_file = std::make_shared<RawVolumeFile>(desc, t.lo, t.hi, a.vol.load().non_finite);
  OutOfCoreOptions o;
  o.memory_budget = budget;
  o.blocks = a.blocks;
  o.refresh = a.refresh;
  if (!a.block_dims.empty()) o.block_dims = parse_dims(a.block_dims);
  Progress fill_bar("fill blocks", 1.0, a.quiet);
  o.fill_progress = [&](double f) { fill_bar.update(f); };
  t.out_of_core = std::make_shared<OutOfCoreSampler>(t.raw_file, a.seed, o);
  const OutOfCoreSampler& s = *t.out_of_core;
  fill_bar.finish(fmt::format("({} blocks in {:.1f}s)", s.blocks(), s.fill_seconds()));
  if (!a.quiet)
    std::fprintf(stderr,
                 "out-of-core buffer: %lld blocks of %lldx%lldx%lld voxels, %lld replaced per step; %s held of a %s "
                 "budget\n",
                 (long long)s.blocks(), (long long)s.block_dims().x, (long long)s.block_dims().y,
                 (long long)s.block_dims().z, (long long)s.refresh(), human_bytes(double(s.bytes_held())).c_str(),
                 human_bytes(double(budget)).c_str());
  // Regions never loaded are never learned: say so when this run cannot be expected to see
  // (almost) the whole volume (measured: 512^3, 500 steps, 64 MiB budget, coverage 50% -> 6 dB
  // below in-core; --refresh 50 for 96% -> 2.4 dB).
  if (a.steps > 0 && !a.quiet) {
    const double cover = s.expected_coverage(a.steps);
    if (cover < 0.95) {
      const int64_t need = int64_t(std::ceil(3.0 * double(s.volume_blocks()) / double(a.steps)));
      const int64_t max_refresh = std::max<int64_t>(1, s.blocks() / 2);
      const std::string fix =
          need <= max_refresh
              ? fmt::format("--refresh {} covers about 95%", need)
              : fmt::format("{} steps with --refresh {} cover about 95%",
                            int64_t(std::ceil(3.0 * double(s.volume_blocks()) / double(max_refresh))), max_refresh);
      std::fprintf(stderr,
                   "note: over %lld steps the buffer is expected to load only %.0f%% of the volume's %lld blocks, "
                   "and regions never loaded are not learned; %s\n",
                   (long long)a.steps, 100 * cover, (long long)s.volume_blocks(), fix.c_str());
    }
  }
  t.sampler = t.out_of_core;
  return t;
}

// A buffer concentrates each step's samples on the resident fraction f of the volume, so every
// hash-grid entry it touches gets many consistent gradients and Adam moves it a full step each step;
// with the paper's rate the loss can then spike (README, "Out-of-core training"). "auto" scales the
// grid's rate by f, at least 0.1. Measured on 512^3 noise with the paper config, 64 MiB buffer
// (f = 0.073), 500 steps, 3 seeds each: factor 1 -> 36.6 dB mean with spikes, 0.2 -> 39.4, 0.1 -> 40.2
// without spikes (in-core 40.4). But an under-fitting run (128^3, a ratio-20 config, no spikes) lost
// 1.4 dB with 0.1, so the default stays the configured rate (1).
ModelConfig scale_grid_learning_rate(ModelConfig config, const TrainArgs& a, const OutOfCoreSampler& s) {
  double scale;
  if (a.grid_lr_scale == "auto") {
    scale = std::clamp(s.resident_fraction(), 0.1, 1.0);
  } else {
    char* end = nullptr;
    scale = std::strtod(a.grid_lr_scale.c_str(), &end);
    if (end == a.grid_lr_scale.c_str() || *end || !(scale > 0) || !std::isfinite(scale))
      fail("--grid-lr-scale expects auto or a positive number, got '{}'", a.grid_lr_scale);
  }
  if (scale == 1.0) return config;
  config.adam.non_matrix_learning_rate_factor *= float(scale);
  if (!a.quiet)
    std::fprintf(stderr,
                 "out-of-core: the buffer holds %.1f%% of the volume; grid learning rate scaled by %.3g "
                 "(--grid-lr-scale %s)\n",
                 100 * s.resident_fraction(), scale, a.grid_lr_scale.c_str());
  return config;
}

// --device: "cuda" where the run can train on the GPU (the volume in memory, a grid encoding with ReLU
// layers, no live previews), else one clear error; "auto" takes the GPU when there is one and the run
// allows it, and says why not when it does not.
Device choose_device(const TrainArgs& a, const TrainingData& data, const Network& net, bool preview) {
  const Device asked = cuda::resolve_device(a.device);
  if (asked == Device::Cpu) return Device::Cpu;
  std::string why_not;
  if (!data.vol) why_not = "--device cuda trains volumes held in memory (--sampler incore); this run samples " + data.kind;
  if (preview) why_not = "--preview-* options run on the CPU trainer";
  const uint64_t need = cuda::GpuTrainer::bytes_needed(net, data.dims.count(), a.batch);
  if (why_not.empty() && cuda::free_memory_bytes() < need)
    why_not = fmt::format("the GPU has {} free, training needs about {} for this volume and batch",
                          human_bytes(double(cuda::free_memory_bytes())), human_bytes(double(need)));
  if (why_not.empty()) why_not = cuda::unsupported_reason(net);
  if (why_not.empty()) return Device::Cuda;
  if (a.device == "cuda") fail("{}; use --device cpu", why_not);
  if (!a.quiet) std::fprintf(stderr, "note: training on the CPU: %s\n", why_not.c_str());
  return Device::Cpu;
}

void run_train(const TrainArgs& a) {
  set_num_threads(a.threads);
  if (!a.timesteps.empty()) {
    if (a.preview.enabled()) fail("--preview-* options are not supported with --timesteps");
    if (a.device == "cuda") fail("--timesteps trains on the CPU; --device cuda is not supported for time series yet");
    return run_train_series(a);
  }
  // Everything that can be checked without the data is checked first, so mistakes fail fast.
  if (a.batch <= 0 || a.batch % kChunk != 0) fail("--batch must be a positive multiple of {}, got {}", kChunk, a.batch);
  if (a.steps < -1) fail("--steps must be non-negative, got {}", a.steps);
  if (a.macrocell_size < 0) fail("--macrocell-size must be 0 (none) or positive, got {}", a.macrocell_size);
  if (a.eval_samples < 0) fail("--eval-samples must be non-negative, got {}", a.eval_samples);
  if (a.checkpoint_every < 0) fail("--checkpoint-every must be non-negative, got {}", a.checkpoint_every);
  if (a.blocks < 0 || a.refresh < 0) fail("--blocks and --refresh must be positive");
  if (a.continuous || a.switch_every) fail("--continuous and --switch-every need --timesteps");
  if (a.device == "cuda") cuda::require_device();
  const std::optional<PreviewOptions> preview_opts = a.preview.options();  // checks the flags, creates the dir
  const uint64_t budget =
      a.memory_budget.empty() ? available_memory_bytes() / 2 : parse_byte_size(a.memory_budget);
  if (budget == 0) fail("--memory-budget must be positive");
  ModelConfig config = load_config(a.config);
  VolumeDesc desc = describe_volume(a.volume, a.vol.raw());
  TrainingData data = open_training_data(a, desc, budget);
  if (data.hi == data.lo && !a.quiet)
    std::fprintf(stderr, "note: the volume is constant (%g); it is represented as normalised 0\n", data.lo);

  if (a.target_ratio > 0) {
    std::string note;
    config = size_config_for_ratio(config, data.source_bytes(), a.target_ratio, &note);
    if (!a.quiet) std::fprintf(stderr, "%s\n", note.c_str());
  }
  if (data.out_of_core) config = scale_grid_learning_rate(config, a, *data.out_of_core);
  Model model = new_model(config, data.dims, data.dtype, data.lo, data.hi, a.seed);
  Network& net = *model.net;
  if (!a.quiet && a.target_ratio <= 0 && model.param_bytes() > data.source_bytes())
    std::fprintf(stderr, "note: the model (%s) is larger than the volume (%s); use --target-ratio R to compress\n",
                 human_bytes(double(model.param_bytes())).c_str(), human_bytes(double(data.source_bytes())).c_str());

  const int64_t steps = a.steps >= 0 ? a.steps : (a.seconds > 0 ? INT64_MAX : 1000);
  const Device dev = choose_device(a, data, net, preview_opts.has_value());
  std::unique_ptr<CpuTrainer> cpu;
  std::unique_ptr<cuda::GpuTrainer> gpu;
  if (dev == Device::Cuda) {
    if (a.precision != "auto" && !a.quiet)
      std::fprintf(stderr, "note: --precision %s applies to CPU training; the GPU trainer keeps its own arithmetic\n",
                   a.precision.c_str());
    gpu = std::make_unique<cuda::GpuTrainer>(
        net, view_of(*data.vol),
        cuda::GpuTrainOptions{a.batch, a.seed, kChunk, cuda::parse_mlp_path(a.mlp)});
    if (a.macrocell_size > 0) gpu->enable_online_ranges(data.dims, a.macrocell_size);
    if (!a.quiet)
      std::fprintf(stderr, "training on %s (MLP: %s)\n", cuda::devices().at(0).name.c_str(),
                   cuda::mlp_path_name(gpu->mlp_path()));
  } else {
    TrainOptions to{a.batch, a.seed};
    to.precision = resolve_training_precision(a.precision, net);
    cpu = std::make_unique<CpuTrainer>(net, data.sampler, to);
    if (a.macrocell_size > 0) cpu->enable_online_ranges(data.dims, a.macrocell_size);
  }
  // Reports' "precision": the CPU trainer's MLP arithmetic; null on the GPU (its own arithmetic).
  const Json precision_report = cpu ? Json(precision_name(cpu->options().precision)) : Json(nullptr);
  std::unique_ptr<TrainPreview> preview;
  if (preview_opts) preview = std::make_unique<TrainPreview>(*preview_opts, *cpu, data.dims);
  double preview_seconds = 0;  // left out of the training time and samples/s
  std::vector<double> step_seconds;
  // What a saved model records of its training so far (checkpoints, an aborted run, the end).
  auto record_training = [&](int64_t done, double seconds, float loss) {
    model.training = {{"steps", done},          {"seconds", seconds}, {"interrupted", bool(g_interrupted)},
                      {"batch", a.batch},       {"seed", a.seed},     {"final_loss", loss},
                      {"threads", num_threads()}, {"sampler", data.kind}, {"device", device_name(dev)},
                      {"precision", precision_report}};
    if (gpu) {
      gpu->download();  // the model file is written from net.params
      if (gpu->has_online_ranges()) model.macrocells = gpu->online_ranges();
    } else if (cpu->has_online_ranges()) {
      model.macrocells = cpu->online_ranges();
    }
  };
  const bool by_time = a.seconds > 0 && a.steps < 0;
  Progress bar("train", by_time ? a.seconds : double(steps), a.quiet);
  auto t0 = std::chrono::steady_clock::now();
  float loss = 0;
  int64_t done = 0;
  g_interrupted = 0;
  auto previous = std::signal(SIGINT, on_sigint);
  try {
    int group = 1;  // GPU: steps enqueued between synchronisations, grown to ~0.1 s
    while (done < steps && !g_interrupted) {
      auto t_step = std::chrono::steady_clock::now();
      if (gpu) {
        int64_t k = std::min<int64_t>(group, steps - done);
        if (a.checkpoint_every > 0) k = std::min<int64_t>(k, a.checkpoint_every - done % a.checkpoint_every);
        gpu->run(int(k));
        loss = gpu->last_loss();  // synchronises
        const double per = seconds_since(t_step) / double(k);
        for (int64_t i = 0; i < k; ++i) step_seconds.push_back(per);
        done += k;
        if (per * double(group) < 0.1 && group < 1024) group *= 2;
      } else {
        loss = cpu->step();
        step_seconds.push_back(seconds_since(t_step));
        ++done;
      }
      if (preview) preview_seconds += preview->after_step(done);
      double el = seconds_since(t0) - preview_seconds;
      if (!std::isfinite(loss)) fail("training diverged at step {} (loss {}); try a smaller learning rate", done, loss);
      std::string extra = fmt::format("step {} loss {:.5f} {:.2f} M samples/s", done, loss, double(done) * a.batch / el / 1e6);
      if (data.out_of_core) extra += fmt::format(" io wait {:.1f}s", data.out_of_core->io_wait_seconds());
      bar.update(by_time ? el : double(done), extra);
      if (a.checkpoint_every > 0 && done % a.checkpoint_every == 0 && done < steps) {
        record_training(done, el, loss);
        model.training["checkpoint"] = true;
        save_model(a.output, model);
      }
      if (a.seconds > 0 && el >= a.seconds) break;
    }
  } catch (const std::exception& e) {
    // The data went away under us (or similar): keep the training done so far, then report.
    std::signal(SIGINT, previous == SIG_ERR ? SIG_DFL : previous);
    bar.finish();
    if (done == 0) throw;
    record_training(done, seconds_since(t0) - preview_seconds, loss);
    model.training["error"] = e.what();
    save_model(a.output, model);
    fail("{}; the model after {} steps was saved to {} (not evaluated)", e.what(), done, a.output);
  }
  if (preview) preview_seconds += preview->finish(done);  // the final state, unless just written
  const double train_seconds = seconds_since(t0) - preview_seconds;
  std::signal(SIGINT, previous == SIG_ERR ? SIG_DFL : previous);
  bar.finish(fmt::format("({} steps, loss {:.5f})", done, loss));
  if (g_interrupted)
    std::fprintf(stderr, "interrupted after %lld steps: evaluating and saving the model (Ctrl-C again to abort)\n",
                 (long long)done);

  // Evaluation: exact over the volume in memory; a volume that is not in memory gets a PSNR
  // estimate from random voxels (a full pass can take longer than the training did).
  record_training(done, train_seconds, loss);
  Json eval_json;
  double psnr, max_err, max_err_orig;
  std::optional<double> ssim;
  std::string psnr_note;
  if (data.vol) {
    EvalResult ev = evaluate(net, *data.vol, !a.no_ssim, dev);
    psnr = ev.psnr;
    max_err = ev.max_abs_error;
    max_err_orig = ev.max_abs_error_original;
    if (!a.no_ssim) ssim = ev.ssim;
    eval_json = {{"method", "full"}};
  } else if (a.eval_samples > 0) {
    const int64_t n = std::min<int64_t>(a.eval_samples, int64_t(data.dims.count()));
    SampledEval ev = evaluate_sampled(net, desc, data.lo, data.hi, n, a.seed + 1, a.vol.load(), dev);
    psnr = ev.psnr;
    max_err = ev.max_abs_error;
    max_err_orig = ev.max_abs_error_original;
    eval_json = {{"method", "sampled"}, {"samples", ev.samples}, {"psnr_ci95", {ev.psnr_ci95_lo, ev.psnr_ci95_hi}}};
    psnr_note = fmt::format(" (estimated from {} random voxels, 95% interval {:.2f}..{:.2f}; `vnr eval` for the full "
                            "volume)",
                            ev.samples, ev.psnr_ci95_lo, ev.psnr_ci95_hi);
  } else {
    psnr = max_err = max_err_orig = std::nan("");
    eval_json = {{"method", "none"}};
    psnr_note = " (not evaluated: --eval-samples 0)";
  }
  if (std::isfinite(psnr)) model.training["psnr"] = psnr;
  if (ssim) model.training["ssim"] = *ssim;
  save_model(a.output, model);
  const uint64_t model_bytes = file_size(a.output);
  const double ratio = double(data.source_bytes()) / double(model_bytes);
  const double sps = double(done) * a.batch / train_seconds;
  std::printf("trained %lld steps in %.2fs (%.2f M samples/s%s), final loss %.6f\n", (long long)done, train_seconds,
              sps / 1e6, cpu && cpu->options().precision == Precision::BF16 ? ", bf16 MLP" : "", loss);
  if (preview)
    std::printf("previews: %lld PNG(s) in %s, %.2fs (not counted as training time)\n",
                (long long)preview->frames_written(), preview_opts->dir.c_str(), preview_seconds);
  std::printf("PSNR %.2f dB%s", psnr, psnr_note.c_str());
  if (ssim) std::printf(", SSIM %.4f", *ssim);
  std::printf(", max |error| %.4g (%.4g in data units)\n", max_err, max_err_orig);
  std::printf("model %s: %s, %llu parameters; volume %s; compression ratio %s\n", a.output.c_str(),
              human_bytes(double(model_bytes)).c_str(), (unsigned long long)net.n_params(),
              human_bytes(double(data.source_bytes())).c_str(), format_ratio(ratio).c_str());
  Json report = {{"steps", done},
                 {"seconds", train_seconds},
                 {"seconds_per_step", done > 0 ? train_seconds / double(done) : 0.0},
                 {"median_step_seconds", median(step_seconds)},
                 {"step_seconds", step_seconds},
                 {"samples_per_second", sps},
                 {"final_loss", loss},
                 {"psnr", psnr},
                 {"ssim", ssim ? Json(*ssim) : Json(nullptr)},
                 {"evaluation", eval_json},
                 {"max_abs_error", max_err},
                 {"n_params", net.n_params()},
                 {"model_bytes", model_bytes},
                 {"volume_bytes", data.source_bytes()},
                 {"compression_ratio", ratio},
                 {"batch", a.batch},
                 {"threads", num_threads()},
                 {"sampler", data.kind},
                 {"memory_budget", budget},
                 {"loss_history", gpu ? gpu->losses() : cpu->loss_history()},
                 {"device", device_name(dev)},
                 {"precision", precision_report},
                 {"preview_seconds", preview_seconds},
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
  write_report(a.report, report);
}

}  // namespace

Model new_model(const ModelConfig& config, Int3 dims, DType dtype, double lo, double hi, uint32_t seed) {
  Model model;
  model.net = std::make_unique<Network>(config);
  model.dims = dims;
  model.source_dtype = dtype;
  model.lo = lo;
  model.hi = hi;
  model.net->init_params(seed);
  return model;
}

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
  add_device_option(c, a->device);
  c->add_option("--mlp", a->mlp, "cuda: MLP implementation, auto (fused when the width allows), fused or cublas")
      ->check(CLI::IsMember({"auto", "fused", "cublas"}))
      ->capture_default_str();
  add_training_precision_option(c, a->precision);
  c->add_option("--report", a->report, "write a JSON report");
  c->add_option("--macrocell-size", a->macrocell_size,
                 "voxels per macro-cell of the value ranges recorded from the training samples for rendering (0: none)")
      ->capture_default_str();
  c->add_option("--sampler", a->sampler,
                 "where training samples come from: incore (volume in memory), outofcore (random block buffer "
                 "refreshed by background reads), mmap (memory-mapped file; the paper's baseline). Default: incore "
                 "when the volume fits the memory budget, else outofcore")
      ->check(CLI::IsMember({"incore", "outofcore", "mmap"}));
  c->add_option("--memory-budget", a->memory_budget,
                "memory for the training data, e.g. 16MiB, 2GiB (default: half of the available memory)");
  c->add_option("--blocks", a->blocks, "outofcore: blocks in the buffer (default 65536, scaled down to the budget)");
  c->add_option("--refresh", a->refresh, "outofcore: blocks replaced per step (default blocks/4, at most 1024; the paper used 1024 of 65536)");
  c->add_option("--grid-lr-scale", a->grid_lr_scale,
                "outofcore: factor on the hash grid's learning rate, or auto = the fraction of the volume in the "
                "buffer (at least 0.1); try auto or 0.1-0.3 when the loss spikes (see README)")
      ->capture_default_str();
  c->add_option("--block-dims", a->block_dims,
                "outofcore: interior voxels of a block X,Y,Z (default 256 along x, y = z for about 64 KiB of data)");
  c->add_option("--eval-samples", a->eval_samples,
                "when the volume is not in memory: random voxels of the final PSNR estimate (0: no evaluation)")
      ->capture_default_str();
  c->add_option("--checkpoint-every", a->checkpoint_every,
                "write the model (atomically) every N steps while training, not only at the end");
  c->add_option("--timesteps", a->timesteps,
                 "train a time series: all, A-B or A,B,C; one model per timestep in the -o directory, each "
                 "warm-started from the previous one");
  c->add_flag("--continuous", a->continuous,
              "with --timesteps: keep training one network while the target timestep advances every "
              "--switch-every steps (fixed learning rate), reporting the steps PSNR takes to recover");
  c->add_option("--switch-every", a->switch_every, "with --continuous: training steps per timestep");
  c->add_flag("--no-ssim", a->no_ssim, "skip the 3-D SSIM of the final evaluation");
  c->add_flag("-q,--quiet", a->quiet, "no progress output");
  a->vol.add(c);
  a->preview.add(c);
  c->callback([a]() { run_train(*a); });
}

}  // namespace vnr::cli
