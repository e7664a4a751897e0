#pragma once
#include <cstdint>
#include <vector>
#include "vnr/memory.h"
#include "vnr/model_config.h"

namespace vnr {

// tiny-cuda-nn's Adam (docs/semantics.md A.7.1) wrapped in ExponentialDecay (A.7.2), binary32 master
// weights, loss scale 1. Parameters [0, n_matrix) are "matrix" params (MLP weights, l2_reg applies);
// the rest are "non-matrix" (grid) params, skipped when their gradient is exactly zero (lazy Adam:
// moments, per-parameter step counter and weight stay as they are).
// The host arithmetic of one optimizer step, shared by every backend's Adam.
struct AdamStepScalars {
  float lr, lo, hi;  // learning rate of this step (before the non-matrix factor); AdaBound's clamp
};
// For the step after t completed steps: updates the ExponentialDecay factor in place (docs/semantics.md A.7.2)
// and returns the step's learning rate and clamp (lo = 0, hi = FLT_MAX unless AdaBound).
AdamStepScalars adam_step_scalars(const AdamConfig& a, const DecayConfig& d, uint64_t t, float* factor);
// Appends sqrtf(1 - beta2^c) and 1 - beta1^c for c = size() .. n-1 (entry 0 is 0): the bias corrections
// by per-parameter step count.
void extend_adam_bias_tables(const AdamConfig& a, size_t n, std::vector<float>& bias_sqrt,
                             std::vector<float>& bias_den);

class Adam {
public:
  Adam(const AdamConfig& adam, const DecayConfig& decay, uint64_t n_params, uint64_t n_matrix);
  // One optimizer step. Reads grads and sets them back to zero (the next step accumulates from 0).
  // When non_matrix_half is given it receives fp16(params) of the non-matrix (grid) parameters.
  void step(float* params, float* grads, uint16_t* non_matrix_half = nullptr);
  uint64_t steps_done() const { return step_; }
  float current_learning_rate() const { return base_lr_ * factor_ * multiplier_; }
  // Scales every following step's learning rate (a session's cool-down: train/session.h); 1 = none.
  void set_lr_multiplier(float m) { multiplier_ = m; }
  // Learning rate used by step t (t = steps completed before it), closed form for reports.
  static float learning_rate_at(const AdamConfig& a, const DecayConfig& d, uint64_t t);

  big_vector<float> m, v;
  big_vector<uint32_t> c;  // per-parameter step counts

private:
  AdamConfig cfg_;
  DecayConfig decay_;
  uint64_t n_params_, n_matrix_;
  uint64_t step_ = 0;
  float base_lr_, factor_ = 1.0f, multiplier_ = 1.0f;
  std::vector<float> bias_sqrt_, bias_den_;  // sqrtf(1 - b2^c) and (1 - b1^c), indexed by c
};

}  // namespace vnr
