#pragma once
// tiny-cuda-nn's Adam element update (docs/semantics.md A.7.1), single-source: the CPU's scalar path and
// the CUDA adam_kernel call adam_update(); the CPU's Highway vector path keeps its own lane-wise form
// of the same operations, checked bit for bit against adam_update() by tests/test_encodings.cpp.
// Needs builds without implicit FMA contraction (CMake sets -ffp-contract=off / --fmad=false).
#include <math.h>
#include <cstdint>
#include "vnr/hd.h"

namespace vnr {

// The hyper-parameters of one optimizer step (lr already decayed; lo/hi: AdaBound's clamp, else 0/FLT_MAX).
struct AdamHyper {
  float lr, beta1, beta2, eps, l2, rel, abs_decay, lo, hi;
};

// One parameter's update from its gradient g; bias_sqrt = sqrtf(1 - beta2^c), bias_den = 1 - beta1^c at
// the parameter's new step count c. Matrix parameters get l2; callers skip non-matrix ones whose
// gradient is exactly 0 (lazy Adam), before calling this.
VNR_HD VNR_INLINE void adam_update(const AdamHyper& k, bool matrix, float g, float bias_sqrt, float bias_den, float& w,
                                   float& m, float& v) {
  if (matrix) g = g + k.l2 * w;
  const float mn = k.beta1 * m + (1.0f - k.beta1) * g;
  const float vn = k.beta2 * v + ((1.0f - k.beta2) * g) * g;
  const float lr_t = (k.lr * bias_sqrt) / bias_den;
  float eff = lr_t / (sqrtf(vn) + k.eps);
  eff = fminf(fmaxf(eff, k.lo), k.hi);
  const float wd = (1.0f - k.rel * lr_t) * w - copysignf(k.abs_decay * lr_t, w);
  w = wd - eff * mn;
  m = mn;
  v = vn;
}

}  // namespace vnr
