#pragma once
// vnr's benchmarking API: training and batched-inference throughput of a model configuration on a
// volume, on one device, as `vnr bench train|infer` measures it; and `vnr bench render`'s frame-rate
// table of a renderer (render_benchmark, below).
//
//   vnr::BenchOptions opts;                  // device, seconds, batch, precision, GPU MLP path
//   opts.seconds = 2;
//   vnr::BenchResult r = vnr::benchmark_training(volume, vnr::load_config("small"), opts);
//   print(r.samples_per_second, r.ms_median, r.phases);
//
// Both time whole batches (the median over at least three), then the MLP alone: on the CPU its
// kernels on every thread (GFLOP/s against the per-sample FLOP count, to compare with the machine's
// FMA peak), on the GPU its kernels within the timed work (CUDA events).
#include <cstdint>
#include <functional>
#include <string>
#include <vector>
#include "vnr/device.h"
#include "vnr/model.h"
#include "vnr/model_config.h"
#include "vnr/renderer.h"
#include "vnr/volume.h"

namespace vnr {

struct BenchOptions {
  Device device = Device::Cpu;  // resolved; cuda::resolve_device turns a user's "auto" into one
  double seconds = 10;          // timed duration (at least three batches are timed whatever it is)
  int64_t batch = 65536;        // samples per batch (training: a multiple of 256)
  // CPU arithmetic: training "auto" | "fp32" | "bf16" (resolve_training_precision), inference the same
  // names (Network::set_inference_precision). The GPU runs its own half-precision MLP.
  std::string precision = "auto";
  cuda::MlpPath mlp = cuda::MlpPath::Auto;  // the GPU's MLP implementation
  uint32_t seed = 1337;                     // the model's parameters and the training samples
  // The MLP kernels alone on the CPU: seconds to time them (negative: a quarter of `seconds`, within
  // [0.5, 3]).
  double mlp_seconds = -1;
  // For a progress bar: the seconds of the timed loop elapsed so far, between batches, and once with
  // finished = true when it ends (before the MLP alone is timed).
  std::function<void(double seconds, bool finished)> progress;
};

// One phase of a training step: report key, printed name and milliseconds (CPU: the median over the
// timed steps; GPU: one step timed with CUDA events).
struct BenchPhase {
  std::string key, name;
  double ms = 0;
};

struct BenchResult {
  bool training = false;
  Device device = Device::Cpu;
  int64_t batch = 0;
  uint64_t n_params = 0;
  std::vector<double> batch_seconds;  // every timed batch (GPU training: each step of a group)
  double samples_per_second = 0;      // batch / median
  double ms_median = 0, ms_min = 0, ms_max = 0;
  double mlp_flops_per_sample = 0;    // forward, x3 when training (forward + backward)
  std::vector<BenchPhase> phases;     // training only
  // The CPU: the MLP kernels alone on every thread, the threads, SIMD target and MLP arithmetic.
  double mlp_gflops = 0;
  int threads = 0;
  std::string simd;
  Precision precision = Precision::FP32;
  // The GPU: its name, the MLP implementation, its kernels' TFLOP/s within the timed work, the peak
  // device memory; inference also resident on the GPU (no host transfers) over resident_batch points.
  std::string gpu, mlp_path;
  double mlp_tflops = 0;
  uint64_t peak_gpu_memory_bytes = 0;
  double resident_samples_per_second = 0;
  int64_t resident_batch = 0;
};

// Training steps of a fresh model of `config` on `volume` (held in memory; the GPU samples it itself).
BenchResult benchmark_training(const Volume& volume, const ModelConfig& config, const BenchOptions& options);
// Batches of random points through a fresh model of `config` for `volume` (its dims and range), or
// through `model` (the CPU sets its inference precision to options.precision).
BenchResult benchmark_inference(const Volume& volume, const ModelConfig& config, const BenchOptions& options);
BenchResult benchmark_inference(Model& model, const BenchOptions& options);

// `vnr bench render`'s table, the paper's frame rates: one row per mode x strategy x macro-cells (off,
// then `with`), in that order, each timed over `orbit` (orbit_frame_rate) from the renderer's options
// as they are on entry (the renderer is left with those and no cache). Strategies: "inshader", "streaming", or "cache": a warm brick
// cache of `cache`'s settings, drawn with the execution strategy auto picks for it (the row's strategy
// reads "cache (inshader)"). row(r) is called after each cell.
struct RenderBenchRow {
  RenderMode mode = RenderMode::RayMarch;
  std::string strategy;
  MacroCellMode macrocells = MacroCellMode::Off;
  double fps = 0, field_samples_per_second = 0, host_syncs_per_frame = 0, iterations_per_frame = 0;
};
std::vector<RenderBenchRow> render_benchmark(Renderer& renderer, const std::vector<RenderMode>& modes,
                                             const std::vector<std::string>& strategies, MacroCellMode with,
                                             const RenderOrbit& orbit, const BrickCacheSettings& cache,
                                             const std::function<void(const RenderBenchRow&)>& row = {});
// Streaming ray marching at each K (samples per live ray per iteration), macro-cells `with`.
struct TuneKRow {
  int k = 0;
  double fps = 0, field_samples_per_second = 0, samples_per_frame = 0;
};
std::vector<TuneKRow> tune_samples_per_iteration(Renderer& renderer, const std::vector<int>& ks, MacroCellMode with,
                                                 const RenderOrbit& orbit,
                                                 const std::function<void(const TuneKRow&)>& row = {});

}  // namespace vnr
