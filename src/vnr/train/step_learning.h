#pragma once
// Learned quantization steps (docs/COMPRESSION.md, "Learned steps", --learn-steps): over the
// quantization-aware steps each grid level's step trains with the parameters, on the loss plus lambda
// times the levels' bits under their Laplace priors (rate_term.h), and lambda, the Lagrange
// multiplier, follows the byte budget: it rises while those bits are above what the planned steps
// (which met the budget) gave and falls while below. The final size search keeps the learned ratios
// between the steps and scales them all to the exact budget.
#include <cstdint>
#include <vector>
#include "vnr/nn/param_codec.h"

namespace vnr {

class StepLearner {
public:
  // segments: the planned steps; those before first_segment (the MLP's matrices) and with step 0
  // (stored raw) are left alone. floor: each segment's smallest step; lambda: the bits' starting weight
  // in loss units. The target is the bits of master at these steps.
  StepLearner(const std::vector<float>& master, const std::vector<ParamSegment>& segments, size_t first_segment,
              std::vector<double> floor, double lambda);
  // One training step, grads = dL/d(the quantized parameters): adds lambda * d bits/d theta to grads,
  // moves each step by Adam on d(loss + lambda bits)/d log step, then lambda toward the target bits.
  // The new steps are written into segments.
  void update(const std::vector<float>& master, std::vector<ParamSegment>& segments, float* grads);
  double lambda() const { return lambda_; }
  double bits() const { return bits_; }  // of the last update's parameters and steps
  double target_bits() const { return target_; }

  static constexpr double kLearningRate = 1e-3;  // Adam on log step (5e-3 lost more, docs/benchmarks.md)
  static constexpr double kLambdaRate = 0.05;    // lambda *= exp(rate * (bits / target - 1)) per step

private:
  size_t first_;
  std::vector<double> floor_, m_, v_;
  double lambda_, target_ = 0, bits_ = 0;
  int64_t t_ = 0;
};

}  // namespace vnr
