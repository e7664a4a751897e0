#include "vnr/train/make_trainer.h"
#include <algorithm>
#include <cmath>
#include "vnr/error.h"
#include "vnr/core/parallel.h"
#include "vnr/train/training_data.h"
#include "vnr/units.h"

namespace vnr {
namespace {

// A Sampler's batches for the GPU trainer, drawn as CpuTrainer draws them: begin_step, then every chunk
// of kChunk samples from (seed, step, chunk), chunks in parallel; so the GPU trains on the CPU's samples.
class SamplerBatchSource final : public cuda::HostBatchSource {
public:
  SamplerBatchSource(std::shared_ptr<Sampler> sampler, uint32_t seed) : sampler_(std::move(sampler)), seed_(seed) {}
  void fill(uint64_t step, int64_t batch, float* x, float* y, float* z, float* target) override {
    sampler_->begin_step(step);
    parallel_for(batch / kChunk, [&](int64_t c) {
      const int64_t o = c * kChunk;
      sampler_->sample(seed_, step, uint64_t(c), kChunk, x + o, y + o, z + o, target + o);
    });
  }

private:
  std::shared_ptr<Sampler> sampler_;
  uint32_t seed_;
};

// The GPU backend: cuda::GpuTrainer (plain C++ API; without CUDA its constructor fails with one line),
// sampling a volume it holds, or fed by a host sampler.
class CudaTrainer final : public Trainer {
public:
  CudaTrainer(Network& net, const Volume* vol, std::shared_ptr<Sampler> sampler, const TrainOptions& opts,
              cuda::MlpPath mlp)
      : net_(net), batch_(opts.batch), seed_(opts.seed) {
    const cuda::GpuTrainOptions o{opts.batch, opts.seed, kChunk, mlp};
    if (vol) gpu_ = std::make_unique<cuda::GpuTrainer>(net, view_of(*vol), o);
    else gpu_ = std::make_unique<cuda::GpuTrainer>(net, std::make_shared<SamplerBatchSource>(std::move(sampler), opts.seed), o);
  }
  Device device() const override { return Device::Cuda; }
  bool asynchronous() const override { return true; }
  void run(int64_t n_steps) override {
    for (int64_t left = n_steps; left > 0;) {  // GpuTrainer::run takes an int
      const int k = int(std::min<int64_t>(left, 1 << 30));
      gpu_->run(k);
      left -= k;
    }
  }
  void synchronize() override { gpu_->synchronize(); }
  float last_loss() const override { return gpu_->steps_done() ? gpu_->last_loss() : 0.f; }
  std::vector<float> losses_from(uint64_t first) const override { return gpu_->losses(first); }
  uint64_t steps_done() const override { return gpu_->steps_done(); }
  float current_learning_rate() const override { return gpu_->current_learning_rate(); }
  void set_learning_rate_multiplier(float m) override { gpu_->set_learning_rate_multiplier(m); }
  void enable_online_ranges(Int3 dims, int cell_size) override { gpu_->enable_online_ranges(dims, cell_size); }
  bool has_online_ranges() const override { return gpu_->has_online_ranges(); }
  ValueRangeGrid online_ranges() const override { return gpu_->online_ranges(); }
  void download() override { gpu_->download(); }
  const void* device_half_params() override { return gpu_->device_half_params(); }
  bool has_quantized_steps() const override { return true; }
  void begin_quantized_steps(const std::vector<float>& master, const std::vector<ParamSegment>& segments,
                             size_t first_rate_segment, double rate_weight_per_loss) override {
    gpu_->begin_quantized(master, segments, first_rate_segment, rate_weight_per_loss);
  }
  void end_quantized_steps(std::vector<float>& master) override { gpu_->end_quantized(master); }
  Network& network() override { return net_; }
  int64_t batch() const override { return batch_; }
  uint32_t seed() const override { return seed_; }
  std::optional<Precision> mlp_precision() const override { return std::nullopt; }
  void set_phase_timing(bool on) override {
    timing_ = on;
    gpu_->set_profiling(on);
  }
  std::vector<PhaseTime> last_step_phases() const override {
    if (!timing_) return {};
    const std::vector<double> s = gpu_->phase_seconds();
    // Keys of their own: a report of the builds before the side stream times other work under
    // "mlp_forward_loss_backward" and "grid_backward".
    static const char* const keys[] = {"sample_encode", "mlp_forward_loss_backward_data",
                                       "grid_backward_beside_weight_gradients", "optimizer"};
    // The grid's backward runs beside the MLP's weight gradients (cuda/gradient_pass.cuh): one phase.
    static const char* const names[] = {"sample+encode", "MLP fwd+loss+bwd through the layers",
                                        "grid backward | MLP weight gradients", "Adam"};
    std::vector<PhaseTime> out;
    for (size_t i = 0; i < s.size() && i < 4; ++i) out.push_back({keys[i], names[i], s[i]});
    return out;
  }
  std::string mlp_path_name() const override { return cuda::mlp_path_name(gpu_->mlp_path()); }
  uint64_t peak_device_memory_bytes() const override { return gpu_->peak_memory_bytes(); }
  std::string device_summary() const override {
    return fmt::format("{} (MLP: {})", cuda::devices().at(0).name, cuda::mlp_path_name(gpu_->mlp_path()));
  }

private:
  Network& net_;
  int64_t batch_;
  uint32_t seed_;
  bool timing_ = false;
  std::unique_ptr<cuda::GpuTrainer> gpu_;  // its queries synchronise (non-const); the wrapper's do not change it
};

}  // namespace

std::unique_ptr<Trainer> make_trainer(Device device, Network& net, std::shared_ptr<Sampler> sampler,
                                      const Volume* in_memory, const TrainOptions& opts, cuda::MlpPath mlp) {
  if (device == Device::Cuda) {
    if (!in_memory && !sampler) fail("the GPU trainer needs a volume in memory or a sampler");
    return std::make_unique<CudaTrainer>(net, in_memory, std::move(sampler), opts, mlp);
  }
  if (!sampler) fail("the CPU trainer needs a sampler");
  return std::make_unique<CpuTrainer>(net, std::move(sampler), opts);
}

DeviceChoice choose_training_device(const std::string& asked_name, const Network& net, Int3 dims, bool in_memory,
                                    int64_t batch,
                                    const std::string& cpu_only_reason) {
  const Device asked = cuda::resolve_device(asked_name);
  if (asked == Device::Cpu) return {};
  std::string why_not = cpu_only_reason;
  // A volume out of memory stays on the host: its sampler feeds the GPU's steps.
  const uint64_t need = cuda::GpuTrainer::bytes_needed(net, in_memory ? dims.count() : 0, batch);
  if (why_not.empty() && cuda::free_memory_bytes() < need)
    why_not = fmt::format("the GPU has {} free, training needs about {} for this volume and batch",
                          human_bytes(double(cuda::free_memory_bytes())), human_bytes(double(need)));
  if (why_not.empty()) why_not = cuda::unsupported_reason(net);
  if (why_not.empty()) return {Device::Cuda, ""};
  if (asked_name == "cuda") fail("{}; use --device cpu", why_not);
  return {Device::Cpu, "training on the CPU: " + why_not};
}

}  // namespace vnr
