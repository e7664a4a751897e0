#include "vnr/nn/optimizer.h"
#include <algorithm>
#include <cfloat>
#include <cmath>
#include "vnr/core/parallel.h"
#include "vnr/nn/cpu_kernels.h"

namespace vnr {

Adam::Adam(const AdamConfig& adam, const DecayConfig& decay, uint64_t n_params, uint64_t n_matrix)
    : m(n_params, 0.0f), v(n_params, 0.0f), c(n_params, 0u), cfg_(adam), decay_(decay), n_params_(n_params),
      n_matrix_(n_matrix), base_lr_(adam.learning_rate) {}

float Adam::learning_rate_at(const AdamConfig& a, const DecayConfig& d, uint64_t t) {
  float f = 1.0f;
  if (d.enabled)
    for (uint64_t s = d.decay_start; s <= t && s <= d.decay_end; s += d.decay_interval) f *= d.decay_base;
  return a.learning_rate * f;
}


AdamStepScalars adam_step_scalars(const AdamConfig& a, const DecayConfig& d, uint64_t t, float* factor) {
  if (d.enabled) {
    if (t == 0) *factor = 1.0f;
    if (t >= d.decay_start && (t - d.decay_start) % d.decay_interval == 0 && t <= d.decay_end) *factor *= d.decay_base;
  }
  AdamStepScalars s{a.learning_rate * *factor, 0.0f, FLT_MAX};
  if (a.adabound) {
    const float c = float(t + 1);
    s.lo = 0.1f - 0.1f / ((1.0f - a.beta2) * c + 1.0f);
    s.hi = 0.1f + 0.1f / ((1.0f - a.beta2) * c);
  }
  return s;
}

void extend_adam_bias_tables(const AdamConfig& a, size_t n, std::vector<float>& bias_sqrt,
                             std::vector<float>& bias_den) {
  while (bias_sqrt.size() < n) {
    const float c = float(bias_sqrt.size());
    bias_sqrt.push_back(bias_sqrt.empty() ? 0.0f : std::sqrt(1.0f - std::pow(a.beta2, c)));
    bias_den.push_back(bias_den.empty() ? 0.0f : 1.0f - std::pow(a.beta1, c));
  }
}

void Adam::step(float* params, float* grads, uint16_t* non_matrix_half) {
  AdamStepScalars sc = adam_step_scalars(cfg_, decay_, step_, &factor_);
  sc.lr *= multiplier_;
  ++step_;
  // Bias corrections up to c = step_ (a parameter's count never exceeds the global step).
  extend_adam_bias_tables(cfg_, step_ + 1, bias_sqrt_, bias_den_);
  // Matrix (MLP) parameters first: l2 applies and they are never skipped.
  kernels::AdamStep ks{{sc.lr, cfg_.beta1, cfg_.beta2, cfg_.epsilon, cfg_.l2_reg, cfg_.relative_decay,
                        cfg_.absolute_decay, sc.lo, sc.hi},
                       true,
                       bias_sqrt_.data(),
                       bias_den_.data()};
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
  // Ranges of at most 2^16, and no more than an even share per thread (small grids: one range each),
  // claimed by whichever thread is free (a core shared with another job takes fewer).
  const int64_t share = (n_nm + num_threads() - 1) / num_threads();
  parallel_for_claimed(n_nm, std::min<int64_t>(int64_t(1) << 16, (share + 63) / 64 * 64), [&](int64_t b, int64_t e) {
    kernels::adam_range(ks, p + b, g + b, mm + b, vv + b, cc + b, non_matrix_half ? non_matrix_half + b : nullptr, e - b);
  });
}

}  // namespace vnr
