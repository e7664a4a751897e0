// Training and inference throughput (include/vnr/benchmark.h): whole batches through the library's
// Trainer backends and ModelQuery, timed from the host, then the MLP kernels alone.
#include "vnr/benchmark.h"
#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include "vnr/error.h"
#include "vnr/core/parallel.h"
#include "vnr/progress.h"
#include "vnr/core/rng.h"
#include "vnr/cuda/cuda.h"
#include "vnr/nn/mlp_kernels.h"
#include "vnr/train/make_trainer.h"

namespace vnr {
namespace {

void check_options(const BenchOptions& o) {
  if (o.batch <= 0) fail("the benchmark's batch must be a positive number of samples, got {}", o.batch);
  if (!std::isfinite(o.seconds) || o.seconds < 0)
    fail("the benchmark's duration must be a non-negative number of seconds, got {}", o.seconds);
  if (o.device == Device::Cuda && cuda::devices().empty()) fail("no CUDA device: {}", cuda::no_device_reason());
}

// Times run_batches(n) (n batches, done when it returns) until options.seconds have passed and at
// least three batches are timed: the seconds of each batch. With grow, groups start at `group` batches
// and double while a group takes under 0.1 s (the GPU: fewer synchronisations). after_group runs
// outside the timed span.
template <class RunBatches, class AfterGroup>
std::vector<double> time_batches(const BenchOptions& o, int group, bool grow, RunBatches&& run_batches,
                                 AfterGroup&& after_group) {
  std::vector<double> times;
  const auto t0 = std::chrono::steady_clock::now();
  while (seconds_since(t0) < o.seconds || times.size() < 3) {
    const auto s0 = std::chrono::steady_clock::now();
    run_batches(group);
    const double per = seconds_since(s0) / group;
    times.insert(times.end(), size_t(group), per);
    after_group();
    if (grow && per * group < 0.1 && group < 1024) group *= 2;
    if (o.progress) o.progress(seconds_since(t0), false);
  }
  if (o.progress) o.progress(seconds_since(t0), true);
  return times;
}

// One worker's share of mlp_gflops: chunks of kChunk samples through the MLP (forward, + backward
// when training) in the arithmetic the benchmark timed, until `seconds` pass. FLOP/s of this thread.
double mlp_flops_one_thread(const Network& net, bool training, Precision train_precision, double seconds,
                            int thread) {
  const MlpLayout& m = net.mlp();
  const int C = kChunk;
  const double flops_per_chunk = net.flops_forward_per_sample() * C * (training ? 3.0 : 1.0);
  std::vector<float> X0(size_t(m.in_pad) * C, 0.5f), acts(net.acts_floats(C)), out(m.n_out * C),
      dout(m.n_out * C, 1e-3f), dW(m.n_params), dX(size_t(m.in_pad) * C), scratch(2 * m.width * C);
  Pcg32 rng(thread + 1);
  for (auto& x : X0) x = rng.next_float();
  const bool bf16 = !training && net.inference_precision() == Precision::BF16;
  const std::vector<uint32_t> wp = bf16 ? net.bf16_weights() : std::vector<uint32_t>();
  std::vector<uint32_t> pairs(bf16 ? net.mlp_bf16_scratch(C) : 0);
  const bool bf16_train = training && train_precision == Precision::BF16;
  Network::Bf16TrainWeights tw;
  if (bf16_train) tw = net.bf16_train_weights();
  std::vector<uint32_t> tws(bf16_train ? net.mlp_train_bf16_scratch(C) : 0);
  const auto t0 = std::chrono::steady_clock::now();
  int64_t chunks = 0;
  while (seconds_since(t0) < seconds) {
    for (int r = 0; r < 16; ++r, ++chunks) {
      if (bf16) {
        net.mlp_forward_bf16(X0.data(), C, wp.data(), pairs.data(), out.data());
        continue;
      }
      if (bf16_train) {
        net.mlp_forward_train_bf16(X0.data(), C, tw, tws.data(), out.data(), out.data());
        net.mlp_backward_train_bf16(dout.data(), C, tw, tws.data(), dW.data(), dX.data());
        continue;
      }
      net.mlp_forward(X0.data(), C, acts.data(), out.data(), out.data());
      if (training) net.mlp_backward(X0.data(), acts.data(), dout.data(), C, dW.data(), dX.data(), scratch.data());
    }
  }
  return chunks * flops_per_chunk / seconds_since(t0);
}

// The MLP alone on every thread: GFLOP/s against the per-sample FLOP count.
double mlp_gflops(const Network& net, bool training, Precision train_precision, double seconds) {
  std::vector<double> per_thread(num_threads(), 0.0);
  parallel_threads([&](int t, int) { per_thread[t] = mlp_flops_one_thread(net, training, train_precision, seconds, t); });
  double total = 0;
  for (double g : per_thread) total += g;
  return total / 1e9;
}

// What every benchmark reports; the rates once batch_seconds holds the timed batches.
BenchResult start_result(bool training, const BenchOptions& o, const Network& net) {
  BenchResult r;
  r.training = training;
  r.device = o.device;
  r.batch = o.batch;
  r.n_params = net.n_params();
  r.mlp_flops_per_sample = net.flops_forward_per_sample() * (training ? 3.0 : 1.0);
  if (o.device == Device::Cuda) r.gpu = cuda::devices().at(0).name;
  return r;
}

void finish_rates(BenchResult& r) {
  const double med = upper_median(r.batch_seconds);
  r.samples_per_second = double(r.batch) / med;
  r.ms_median = med * 1e3;
  r.ms_min = *std::min_element(r.batch_seconds.begin(), r.batch_seconds.end()) * 1e3;
  r.ms_max = *std::max_element(r.batch_seconds.begin(), r.batch_seconds.end()) * 1e3;
}

// The CPU's MLP kernels alone, its threads, SIMD target and MLP arithmetic.
void finish_cpu(BenchResult& r, const Network& net, Precision precision, const BenchOptions& o) {
  const double seconds = o.mlp_seconds >= 0 ? o.mlp_seconds : std::min(3.0, std::max(0.5, o.seconds / 4));
  r.precision = precision;
  r.mlp_gflops = mlp_gflops(net, r.training, precision, seconds);
  r.threads = num_threads();
  r.simd = kernels::simd_target_name();
}

// The GPU's MLP kernels within the timed work: `mlp_seconds` per batch for `share` of the MLP's flops.
void finish_gpu(BenchResult& r, double mlp_seconds, double share = 1.0) {
  r.mlp_tflops = share * r.mlp_flops_per_sample * double(r.batch) / mlp_seconds / 1e12;
}

}  // namespace

BenchResult benchmark_training(const Volume& volume, const ModelConfig& config, const BenchOptions& o) {
  check_options(o);
  Model model = create_model(config, volume, o.seed);
  Network& net = *model.net;
  const bool gpu = o.device == Device::Cuda;
  TrainOptions to{o.batch, o.seed};
  if (!gpu) to.precision = resolve_training_precision(o.precision, net);
  BenchResult r = start_result(true, o, net);
  std::shared_ptr<Sampler> sampler;
  if (!gpu) sampler = std::make_shared<InCoreSampler>(volume);
  std::unique_ptr<Trainer> tr = make_trainer(o.device, net, sampler, &volume, to, o.mlp);
  tr->run(gpu ? 5 : 2);  // warm-up: page-in, caches, the GPU's first launches
  tr->synchronize();
  std::vector<std::vector<double>> phase_seconds;  // the CPU's, per phase, per timed step
  r.batch_seconds = time_batches(
      o, gpu ? 8 : 1, gpu,
      [&](int n) {
        tr->run(n);
        tr->synchronize();
      },
      [&] {
        if (gpu) return;
        const std::vector<Trainer::PhaseTime> ph = tr->last_step_phases();
        phase_seconds.resize(ph.size());
        for (size_t p = 0; p < ph.size(); ++p) phase_seconds[p].push_back(ph[p].seconds);
      });
  if (gpu) {  // one step timed phase by phase (CUDA events)
    tr->set_phase_timing(true);
    tr->run(1);
  }
  const std::vector<Trainer::PhaseTime> last = tr->last_step_phases();
  for (size_t p = 0; p < last.size(); ++p)
    r.phases.push_back({last[p].key, last[p].name, (gpu ? last[p].seconds : upper_median(phase_seconds[p])) * 1e3});
  finish_rates(r);
  if (!gpu) {
    finish_cpu(r, net, to.precision, o);
    return r;
  }
  if (r.phases.size() < 2) fail("the GPU trainer timed no phases");
  // Phase 1: the MLP's forward, loss and backward through the layers, two of the training's three
  // forward-sized GEMMs; the weight gradients run beside the grid's backward (cuda/gradient_pass.cuh).
  finish_gpu(r, r.phases[1].ms / 1e3, 2.0 / 3.0);
  r.mlp_path = tr->mlp_path_name();
  r.peak_gpu_memory_bytes = tr->peak_device_memory_bytes();
  return r;
}

BenchResult benchmark_inference(Model& model, const BenchOptions& o) {
  check_options(o);
  if (!model.net) fail("the model has no network");
  Network& net = *model.net;
  const bool gpu = o.device == Device::Cuda;
  if (!gpu) net.set_inference_precision(parse_precision(o.precision));
  BenchResult r = start_result(false, o, net);
  ModelQuery query(model, o.device, o.mlp);
  std::vector<float> coords(3 * o.batch), out(o.batch);
  Pcg32 rng(7);
  for (auto& c : coords) c = rng.next_float();
  query.points(coords.data(), o.batch, out.data());  // warm-up
  r.batch_seconds = time_batches(
      o, 1, false, [&](int) { query.points(coords.data(), o.batch, out.data()); }, [] {});
  finish_rates(r);
  if (!gpu) {
    finish_cpu(r, net, net.inference_precision(), o);
    return r;
  }
  cuda::GpuNetwork& gn = *query.gpu();
  r.resident_batch = std::max<int64_t>(o.batch, int64_t(1) << 22);  // enough work to fill the GPU
  const cuda::GpuNetwork::ResidentTiming rt = gn.time_resident(r.resident_batch, 20);
  r.resident_samples_per_second = double(r.resident_batch) / rt.seconds;
  finish_gpu(r, rt.mlp_seconds * double(o.batch) / double(r.resident_batch));
  r.mlp_path = cuda::mlp_path_name(gn.mlp_path());
  r.peak_gpu_memory_bytes = gn.peak_memory_bytes();
  return r;
}

BenchResult benchmark_inference(const Volume& volume, const ModelConfig& config, const BenchOptions& o) {
  check_options(o);
  Model model = create_model(config, volume, o.seed);
  return benchmark_inference(model, o);
}

}  // namespace vnr
