// vnr bench train|infer: parses the options, runs the benchmarking API (include/vnr/benchmark.h) and
// prints its result: throughput on a real volume, median over timed steps, plus the MLP alone.
#include <cstdio>
#include <string>
#include <fmt/format.h>
#include "cli.h"
#include "vnr/benchmark.h"
#include "vnr/threads.h"
#include "vnr/progress.h"
#include "vnr/device.h"
#include "vnr/units.h"

namespace vnr::cli {
namespace {

struct BenchArgs {
  std::string what, volume, config = "paper", report, device = "auto", mlp = "auto", precision = "auto";
  double seconds = 10;
  int64_t batch = 65536;
  int threads = 0;
  VolumeArgs vol;
};

// "name ms, name ms, ..." of a training benchmark's phases.
std::string phase_line(const BenchResult& r, int decimals) {
  std::string line;
  for (size_t p = 0; p < r.phases.size(); ++p)
    line += fmt::format("{}{} {:.{}f}", p ? ", " : "", r.phases[p].name, r.phases[p].ms, decimals);
  return line;
}

Json phase_json(const BenchResult& r) {
  Json ph = Json::object();
  for (const BenchPhase& p : r.phases) ph[p.key] = p.ms;
  return ph;
}

// The GPU's lines and report keys: per-step times from groups of steps between synchronisations,
// inference both with host transfers (the batch comes from and goes back to host memory) and resident
// on the GPU (no transfers).
void print_bench_cuda(const BenchArgs& a, const BenchResult& r) {
  const bool training = r.training;
  const double flops = r.mlp_flops_per_sample, sps = r.samples_per_second;
  if (training) {
    std::printf("phases of one step (ms, CUDA events): %s\n", phase_line(r, 3).c_str());
  }
  std::printf("%s %s on %s: %.1f M samples/s (median of %zu batches of %lld, %.3f ms each)%s\n", a.what.c_str(),
              a.config.c_str(), r.gpu.c_str(), sps / 1e6, r.batch_seconds.size(), (long long)r.batch, r.ms_median,
              training ? "" : " with host transfers");
  if (!training) std::printf("resident on the GPU: %.1f M samples/s\n", r.resident_samples_per_second / 1e6);
  std::printf("MLP (%s path): %.1f kFLOP/sample, %.2f TFLOP/s in its kernels; %.2f TFLOP/s end to end; peak GPU "
              "memory %s\n",
              r.mlp_path.c_str(), flops / 1e3, r.mlp_tflops, flops * sps / 1e12,
              human_bytes(double(r.peak_gpu_memory_bytes)).c_str());
  Json report = {{"mode", a.what},
                 {"device", "cuda"},
                 {"config", a.config},
                 {"batch", r.batch},
                 {"n_params", r.n_params},
                 {"gpu", r.gpu},
                 {"samples_per_second", sps},
                 {"batches", r.batch_seconds.size()},
                 {"ms_median", r.ms_median},
                 {"mlp_path", r.mlp_path},
                 {"mlp_flops_per_sample", flops},
                 {"mlp_tflops", r.mlp_tflops},
                 {"tflops_end_to_end", flops * sps / 1e12},
                 {"peak_gpu_memory_bytes", r.peak_gpu_memory_bytes}};
  if (training) {
    report["phase_ms"] = phase_json(r);
  } else {
    report["resident_samples_per_second"] = r.resident_samples_per_second;
    report["resident_batch"] = r.resident_batch;
  }
  write_report(a.report, report);
}

// The CPU's lines and report keys: the median over timed batches, the MLP kernels alone, the phases.
void print_bench_cpu(const BenchArgs& a, const BenchResult& r) {
  const double flops = r.mlp_flops_per_sample, sps = r.samples_per_second;
  std::printf("%s %s%s: %.3f M samples/s (median of %zu batches of %lld, %.2f ms each; min %.2f, max %.2f)\n",
              a.what.c_str(), a.config.c_str(), r.precision == Precision::BF16 ? " (bf16)" : "", sps / 1e6,
              r.batch_seconds.size(), (long long)r.batch, r.ms_median, r.ms_min, r.ms_max);
  std::printf("MLP FLOPs: %.1f kFLOP/sample -> %.1f GFLOP/s end to end; MLP kernels alone: %.1f GFLOP/s on %d threads (%s)\n",
              flops / 1e3, flops * sps / 1e9, r.mlp_gflops, r.threads, r.simd.c_str());
  if (r.training) {
    std::printf("phases (median ms): %s\n", phase_line(r, 2).c_str());
  }
  Json report = {{"mode", a.what},
                 {"device", "cpu"},
                 {"config", a.config},
                 {"samples_per_second", sps},
                 {"batch", r.batch},
                 {"batches", r.batch_seconds.size()},
                 {"ms_median", r.ms_median},
                 {"ms_min", r.ms_min},
                 {"ms_max", r.ms_max},
                 {"mlp_flops_per_sample", flops},
                 {"gflops_end_to_end", flops * sps / 1e9},
                 {"mlp_gflops", r.mlp_gflops},
                 {"threads", r.threads},
                 {"simd", r.simd},
                 {"precision", precision_name(r.precision)},
                 {"n_params", r.n_params}};
  if (r.training) report["phase_ms"] = phase_json(r);
  write_report(a.report, report);
}

void run_bench(const BenchArgs& a) {
  set_num_threads(a.threads);
  BenchOptions o;
  o.device = cuda::resolve_device(a.device);
  o.seconds = a.seconds;
  o.batch = a.batch;
  o.precision = a.precision;
  o.mlp = cuda::parse_mlp_path(a.mlp);
  const Volume vol = open_volume(a.volume, a.vol.open());
  const ModelConfig config = load_config(a.config);
  const bool gpu = o.device == Device::Cuda;
  Progress bar(std::string("bench ") + a.what + (gpu ? " (cuda)" : ""), a.seconds, false);
  o.progress = [&bar](double seconds, bool finished) {
    if (finished) bar.finish();
    else bar.update(seconds);
  };
  const BenchResult r = a.what == "train" ? benchmark_training(vol, config, o) : benchmark_inference(vol, config, o);
  if (gpu) print_bench_cuda(a, r);
  else print_bench_cpu(a, r);
}

}  // namespace

void add_bench(CLI::App& app) {
  CLI::App* bench = app.add_subcommand("bench", "measure training, inference or rendering throughput");
  bench->require_subcommand(1);
  for (const char* what : {"train", "infer"}) {
    auto a = std::make_shared<BenchArgs>();
    a->what = what;
    CLI::App* c = bench->add_subcommand(
        what, std::string(what) == "train" ? "training throughput on a volume" : "batched inference throughput");
    c->add_option("volume", a->volume, "volume to sample")->required();
    c->add_option("--config", a->config, "preset or config file")->capture_default_str();
    c->add_option("--seconds", a->seconds, "timed duration")->capture_default_str();
    c->add_option("--batch", a->batch, "samples per batch")->capture_default_str();
    c->add_option("--threads", a->threads, "CPU threads (default: all cores)");
    c->add_option("--report", a->report, "write a JSON report");
    add_device_option(c, a->device);
    if (std::string(what) == "infer") add_precision_option(c, a->precision);
    else add_training_precision_option(c, a->precision);
    c->add_option("--mlp", a->mlp, "cuda: MLP implementation, auto, fused or cublas")
        ->check(CLI::IsMember({"auto", "fused", "cublas"}))
        ->capture_default_str();
    a->vol.add(c);
    c->callback([a]() { run_bench(*a); });
  }
  add_bench_render(*bench);
  add_bench_rd(*bench);
}

}  // namespace vnr::cli
