#pragma once
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>
#include "vnr/training_options.h"
#include "vnr/core/value_range_grid.h"
#include "vnr/nn/network.h"
#include "vnr/nn/optimizer.h"
#include "vnr/train/sampler.h"
#include "vnr/train/trainer_backend.h"

namespace vnr {

// --precision of training: "fp32", "bf16" (an error where Network::bf16_training_supported() is
// false) or "auto" = fp32 (bf16 training lost up to 0.2 dB on some volumes; docs/benchmarks.md).
// MLPs narrower than kBf16TrainMinWidth also train slower in bf16.
constexpr uint32_t kBf16TrainMinWidth = 32;
Precision resolve_training_precision(const std::string& name, const Network& net);

// Runs training steps on a Network: sample -> encode -> MLP forward -> loss -> MLP backward ->
// grid backward -> Adam. Deterministic for a given seed and thread count.
//
// Parallel structure of a step (2 threads shown; see docs/ARCHITECTURE.md):
//  1. chunks of 256 samples are dealt round-robin to threads; each thread samples, encodes, runs the
//     MLP forward/backward with activations in L2, accumulates its own dW, and stores dL/d(encoding);
//     a small grid's gradient is scattered here too, chunk by chunk, into the thread's own copy. The
//     last TrainOptions::shared_tail_chunks chunks are claimed by whichever thread is free; each keeps
//     its own MLP gradient and its dL/d(encoding);
//  2. grid levels are claimed by whichever thread is free (round-robin into private copies); each
//     thread scatters the gradient of its levels
//     (for every sample; for a small grid, for the shared chunks only, into the thread's copy), so no
//     two threads write the same entry (no atomics);
//  3. the per-thread and per-shared-chunk gradients are summed in a fixed order, then one fused Adam
//     pass updates all parameters (both over element ranges claimed by whichever thread is free).
class CpuTrainer final : public Trainer {
public:
  CpuTrainer(Network& net, std::shared_ptr<Sampler> sampler, TrainOptions opts);
  float step();  // one training step; returns the mean loss of its batch
  uint64_t steps_done() const override { return adam_.steps_done(); }
  float current_learning_rate() const override { return adam_.current_learning_rate(); }
  void set_learning_rate_multiplier(float m) override { adam_.set_lr_multiplier(m); }
  const std::vector<float>& loss_history() const { return loss_history_; }
  Network& network() override { return net_; }
  const TrainOptions& options() const { return opts_; }
  // Online macro-cells (paper "Macro-Cell Optimization"): from now on every training sample widens the
  // value range of its macro-cells (docs/semantics.md B.6); each thread keeps its own grid, merged on request.
  void enable_online_ranges(Int3 dims, int cell_size = 16) override;
  bool has_online_ranges() const override { return !thread_ranges_.empty(); }
  ValueRangeGrid online_ranges() const override;
  // The Trainer interface: run(n) is n step()s; the parameters live in the Network (download: no-op).
  Device device() const override { return Device::Cpu; }
  void run(int64_t n_steps) override;
  float last_loss() const override { return loss_history_.empty() ? 0.f : loss_history_.back(); }
  std::vector<float> losses_from(uint64_t first) const override {
    return {loss_history_.begin() + std::ptrdiff_t(std::min<size_t>(first, loss_history_.size())), loss_history_.end()};
  }
  void download() override {}
  int64_t batch() const override { return opts_.batch; }
  uint32_t seed() const override { return opts_.seed; }
  std::optional<Precision> mlp_precision() const override { return opts_.precision; }
  std::vector<PhaseTime> last_step_phases() const override;
  bool set_gradient_hook(std::function<void(float* grads)> hook) override {
    gradient_hook_ = std::move(hook);
    return true;
  }
  // Seconds spent in each phase of the last step, and what each one holds (report key, printed name):
  // sample+encode+MLP, grid backward, optimizer; a grid scattered per chunk (private copies) counts in
  // the first, except the shared chunks' share, which is the second.
  struct Phase {
    const char* key;
    const char* name;
  };
  std::array<Phase, 3> phases() const;
  double phase_seconds[3] = {0, 0, 0};

private:
  void scatter_grid_gradients(int64_t n_static);  // step()'s grid backward after the chunks
  void sum_gradients();                            // step()'s per-thread gradients into grads_
  Network& net_;
  std::shared_ptr<Sampler> sampler_;
  std::function<void(float* grads)> gradient_hook_;
  TrainOptions opts_;
  Adam adam_;
  int n_threads_;
  big_vector<float> grads_;              // full gradient (MLP part overwritten each step)
  bool private_grid_grads_ = false;  // TrainOptions::private_grid_grad_max_bytes
  std::vector<std::vector<float>> dW_;    // per-thread gradient: the MLP's, and the grid's if private
  std::vector<std::vector<float>> ws_;    // per-thread chunk workspace
  std::vector<std::vector<uint32_t>> bf16_ws_;  // per-thread bf16 chunk workspace (BF16 training)
  Network::Bf16TrainWeights bf16_w_;             // this step's weights in bf16 (BF16 training)
  std::vector<float> xs_, ys_, zs_;
  big_vector<float> dEnc_;  // the whole batch's dL/dX0 (per-level grid backward only; 64-byte aligned rows)
  int64_t n_tail_ = 0;             // shared chunks at the end of each step (TrainOptions::shared_tail_chunks)
  std::vector<float> tail_dW_;     // their MLP gradients, n_tail_ x n_mlp
  big_vector<float> tail_dEnc_;    // their dL/dX0 when the grid is private (else in dEnc_)
  std::vector<double> chunk_loss_;
  std::vector<float> loss_history_;
  std::vector<ValueRangeGrid> thread_ranges_;
};

}  // namespace vnr
