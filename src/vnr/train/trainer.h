#pragma once
#include <cstdint>
#include <memory>
#include <string>
#include <vector>
#include "vnr/nn/network.h"
#include "vnr/nn/optimizer.h"
#include "vnr/train/sampler.h"
#include "vnr/volume/value_range_grid.h"

namespace vnr {

struct TrainOptions {
  int64_t batch = 65536;  // samples per step, a multiple of kChunk (256)
  uint32_t seed = 1337;   // initialisation and sampling
  // BF16: the MLP's forward and backward with bf16 operands and fp32 sums (Network::
  // mlp_forward_train_bf16; needs Network::bf16_training_supported()). The loss, the grid, the
  // master weights and Adam stay fp32.
  Precision precision = Precision::FP32;
};

// --precision of training: "fp32", "bf16" (an error where Network::bf16_training_supported() is
// false) or "auto": bf16 where supported and the MLP is at least kBf16TrainMinWidth wide. (Measured,
// bonsai steps: 32 wide 1.1x, 64 wide 1.4x, 128 wide 1.4-1.6x faster in bf16; 16 wide 1.6x slower,
// its layout conversions costing more than its tiny products save. README, "bf16 training".)
constexpr uint32_t kBf16TrainMinWidth = 32;
Precision resolve_training_precision(const std::string& name, const Network& net);

// Runs training steps on a Network: sample -> encode -> MLP forward -> loss -> MLP backward ->
// grid backward -> Adam. Deterministic for a given seed and thread count.
//
// Parallel structure of a step (2 threads shown; see docs/ARCHITECTURE.md):
//  1. chunks of 256 samples are dealt round-robin to threads; each thread samples, encodes, runs the
//     MLP forward/backward with activations in L2, accumulates its own dW, and stores dL/d(encoding);
//  2. grid levels are dealt round-robin to threads; each thread scatters the gradient of its levels
//     for every sample, so no two threads write the same entry (no atomics, no reduction buffers);
//  3. the per-thread dW are summed in thread order, then one fused Adam pass updates all parameters.
class Trainer {
public:
  Trainer(Network& net, std::shared_ptr<Sampler> sampler, TrainOptions opts);
  float step();  // one training step; returns the mean loss of its batch
  uint64_t steps_done() const { return adam_.steps_done(); }
  float current_learning_rate() const { return adam_.current_learning_rate(); }
  const std::vector<float>& loss_history() const { return loss_history_; }
  Network& network() { return net_; }
  const TrainOptions& options() const { return opts_; }
  // Online macro-cells (paper "Macro-Cell Optimization"): from now on every training sample widens the
  // value range of its macro-cells (compat.md B.6); each thread keeps its own grid, merged on request.
  void enable_online_ranges(Int3 dims, int cell_size = 16);
  bool has_online_ranges() const { return !thread_ranges_.empty(); }
  ValueRangeGrid online_ranges() const;
  // Seconds spent in each phase of the last step (sample+MLP, grid backward, optimizer).
  double phase_seconds[3] = {0, 0, 0};

private:
  Network& net_;
  std::shared_ptr<Sampler> sampler_;
  TrainOptions opts_;
  Adam adam_;
  int n_threads_;
  big_vector<float> grads_;              // full gradient (MLP part overwritten each step)
  std::vector<std::vector<float>> dW_;    // per-thread MLP gradient
  std::vector<std::vector<float>> ws_;    // per-thread chunk workspace
  std::vector<std::vector<uint32_t>> bf16_ws_;  // per-thread bf16 chunk workspace (BF16 training)
  Network::Bf16TrainWeights bf16_w_;             // this step's weights in bf16 (BF16 training)
  std::vector<float> xs_, ys_, zs_, dEnc_;
  std::vector<double> chunk_loss_;
  std::vector<float> loss_history_;
  std::vector<ValueRangeGrid> thread_ranges_;
};

}  // namespace vnr
