#include "vnr/nn/optimizer.h"
#include <cfloat>
#include <cmath>
#include "vnr/core/parallel.h"

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

namespace {

struct AdamConsts {
  float lr, lr_nm, beta1, beta2, eps, l2, rel, abs_, lo, hi;
};

// The per-element update, shared by the matrix and grid loops. Returns false to skip.
inline void adam_update(const AdamConsts& k, float lr, float g, float& w, float& m, float& v, uint32_t& c,
                        const float* bsq, const float* bden) {
  m = k.beta1 * m + (1.0f - k.beta1) * g;
  v = k.beta2 * v + (1.0f - k.beta2) * g * g;
  c += 1;
  float lr_t = lr * bsq[c] / bden[c];
  float eff = lr_t / (std::sqrt(v) + k.eps);
  eff = eff < k.lo ? k.lo : (eff > k.hi ? k.hi : eff);
  float wd = (1.0f - k.rel * lr_t) * w - std::copysign(k.abs_ * lr_t, w);
  w = wd - eff * m;
}

}  // namespace

void Adam::step(float* params, float* grads) {
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
  AdamConsts k;
  k.lr = base_lr_ * factor_;
  k.lr_nm = k.lr * cfg_.non_matrix_learning_rate_factor;
  k.beta1 = cfg_.beta1;
  k.beta2 = cfg_.beta2;
  k.eps = cfg_.epsilon;
  k.l2 = cfg_.l2_reg;
  k.rel = cfg_.relative_decay;
  k.abs_ = cfg_.absolute_decay;
  k.lo = 0.0f;
  k.hi = FLT_MAX;
  if (cfg_.adabound) {
    float s = float(step_);
    k.lo = 0.1f - 0.1f / ((1.0f - cfg_.beta2) * s + 1.0f);
    k.hi = 0.1f + 0.1f / ((1.0f - cfg_.beta2) * s);
  }
  const float* bsq = bias_sqrt_.data();
  const float* bden = bias_den_.data();
  float* mm = m.data();
  float* vv = v.data();
  uint32_t* cc = c.data();
  const uint64_t n_mat = n_matrix_;
  const bool opt_mat = cfg_.optimize_matrix_params, opt_nm = cfg_.optimize_non_matrix_params;
  parallel_for_range(int64_t(n_params_), 1 << 15, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) {
      float g = grads[i];
      grads[i] = 0.0f;
      if (uint64_t(i) < n_mat) {
        if (!opt_mat) continue;
        g += k.l2 * params[i];
        adam_update(k, k.lr, g, params[i], mm[i], vv[i], cc[i], bsq, bden);
      } else {
        if (!opt_nm || g == 0.0f) continue;
        adam_update(k, k.lr_nm, g, params[i], mm[i], vv[i], cc[i], bsq, bden);
      }
    }
  });
}

}  // namespace vnr
