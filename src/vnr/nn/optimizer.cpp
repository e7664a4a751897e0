#include "vnr/nn/optimizer.h"
#include <cfloat>
#include <cmath>
#include <algorithm>
#include "vnr/core/parallel.h"
#include "vnr/nn/cpu_kernels.h"

namespace vnr {

Adam::Adam(const AdamConfig& adam, const DecayConfig& decay, uint64_t n_params, uint64_t n_matrix)
    : m(n_params, 0.0f), v(n_params, 0.0f), c(n_params, 0u), cfg_(adam), decay_(decay), n_params_(n_params),
      n_matrix_(n_matrix), base_lr_(adam.learning_rate) {
  bias_sqrt_.push_back(0.0f);
  bias_den_.push_back(0.0f);
}

float Adam::learning_rate_at(const AdamConfig& a, const DecayConfig& d, uint64_t t) {
  float f = 1.0f;
  if (d.enabled)
    for (uint64_t s = d.decay_start; s <= t && s <= d.decay_end; s += d.decay_interval) f *= d.decay_base;
  return a.learning_rate * f;
}


void Adam::step(float* params, float* grads, uint16_t* non_matrix_half) {
  // ExponentialDecay: t = steps completed so far.
  const uint64_t t = step_;
  if (decay_.enabled) {
    if (t == 0) factor_ = 1.0f;
    if (t >= decay_.decay_start && (t - decay_.decay_start) % decay_.decay_interval == 0 && t <= decay_.decay_end)
      factor_ *= decay_.decay_base;
  }
  ++step_;
  // Extend the bias-correction tables to c = step_ (a parameter's count never exceeds the global step).
  while (bias_sqrt_.size() <= step_) {
    float cc = float(bias_sqrt_.size());
    bias_sqrt_.push_back(std::sqrt(1.0f - std::pow(cfg_.beta2, cc)));
    bias_den_.push_back(1.0f - std::pow(cfg_.beta1, cc));
  }
  // Matrix (MLP) parameters first: l2 applies and they are never skipped.
  kernels::AdamStep ks{base_lr_ * factor_, cfg_.beta1, cfg_.beta2, cfg_.epsilon, cfg_.l2_reg, cfg_.relative_decay,
                       cfg_.absolute_decay, 0.0f, FLT_MAX, true, bias_sqrt_.data(), bias_den_.data()};
  if (cfg_.adabound) {
    float s = float(step_);
    ks.lo = 0.1f - 0.1f / ((1.0f - cfg_.beta2) * s + 1.0f);
    ks.hi = 0.1f + 0.1f / ((1.0f - cfg_.beta2) * s);
  }
  if (cfg_.optimize_matrix_params)
    kernels::adam_range(ks, params, grads, m.data(), v.data(), c.data(), nullptr, int64_t(n_matrix_));
  else
    std::fill(grads, grads + n_matrix_, 0.0f);
  // Grid (non-matrix) parameters: skipped where the gradient is exactly 0.
  ks.matrix = false;
  ks.lr *= cfg_.non_matrix_learning_rate_factor;
  const int64_t n_nm = int64_t(n_params_ - n_matrix_);
  float* p = params + n_matrix_;
  float* g = grads + n_matrix_;
  float* mm = m.data() + n_matrix_;
  float* vv = v.data() + n_matrix_;
  uint32_t* cc = c.data() + n_matrix_;
  if (!cfg_.optimize_non_matrix_params) {
    std::fill(g, g + n_nm, 0.0f);
    return;
  }
  parallel_for_range(n_nm, 1 << 16, [&](int64_t b, int64_t e) {
    kernels::adam_range(ks, p + b, g + b, mm + b, vv + b, cc + b, non_matrix_half ? non_matrix_half + b : nullptr, e - b);
  });
}

}  // namespace vnr
