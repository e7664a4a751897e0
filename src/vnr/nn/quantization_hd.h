#pragma once
// The per-parameter arithmetic of quantization-aware and rate-aware training (docs/COMPRESSION.md),
// single-source: the CPU trainer's step hooks (train/rate_control.cpp, train/rate_term.cpp) and the
// CUDA trainer's kernels (cuda/gpu_trainer.cu) call these functions.
#include <cmath>
#include <cstdint>
#include <cstring>
#include "vnr/core/half.h"
#include "vnr/hd.h"
#include "vnr/nn/param_codec.h"

namespace vnr {

// The value a parameter is stored as with quantization step `step` (0: fp16 alone): the nearest
// multiple of the step, at most kMaxQuantIndex steps from 0, rounded to fp16; NaN and inf become 0.
VNR_HD inline float quantized_value(float v, float step) {
  if (step == 0) return half_to_float(float_to_half(v));
  uint32_t bits;
  memcpy(&bits, &v, 4);
  if ((bits & 0x7f800000u) == 0x7f800000u) return 0.0f;
  const float q = fminf(fmaxf(rintf(v / step), -float(kMaxQuantIndex)), float(kMaxQuantIndex));
  return half_to_float(float_to_half(float(int32_t(q)) * step));  // int: -0 becomes +0, as the codec stores it
}

// -log2 of the Laplace(0, scale) mass on [theta - step/2, theta + step/2]; *d receives d/d theta, and
// *dstep (when given) d/d step: how the bits fall as the segment's step grows (learned steps,
// train/step_learning.h).
VNR_HD inline double laplace_bin_bits(double theta, double step, double scale, double* d, double* dstep = nullptr) {
  const double t = fabs(theta), h = 0.5 * step, s = theta < 0 ? -1.0 : 1.0;
  constexpr double kLn2 = 0.69314718055994530942;
  if (t >= h) {  // the bin lies on one side of 0: mass 0.5 e^{-(t-h)/b} (1 - e^{-step/b}), in closed form
    *d = s / (scale * kLn2);
    const double tail = -expm1(-step / scale);  // 1 - e^{-step/b}
    if (dstep) *dstep = -0.5 / (scale * kLn2) - exp(-step / scale) / (scale * tail * kLn2);
    return (1.0 + (t - h) / (scale * kLn2)) - log2(tail);
  }
  // The bin holds 0: mass 1 - 0.5 e^{-(h+t)/b} - 0.5 e^{-(h-t)/b}.
  const double a = exp(-(h + t) / scale), c = exp(-(h - t) / scale);
  const double mass = 1.0 - 0.5 * (a + c);
  const double dmass = 0.5 * (a - c) / scale;  // d mass / d t
  *d = -s * dmass / (mass * kLn2);
  if (dstep) *dstep = -(a + c) / (4 * scale) / (mass * kLn2);  // d mass / d step = (a + c) / (4 b)
  return -log2(mass);
}

// A segment's Laplace scale: its mean |parameter| (the prior's maximum-likelihood fit), at least a
// thousandth of its step.
VNR_HD inline double laplace_scale(double sum_abs, uint64_t count, float step) {
  const double mean = sum_abs / double(count);
  return mean > 1e-3 * double(step) ? mean : 1e-3 * double(step);
}

// The rate term's weight per unit of loss: weight * 2 ln 2 / parameters, the slope of distortion
// against rate of a uniform quantizer at high rate (the loss itself is the last step's).
inline double rate_weight_per_loss(double weight, uint64_t n_params) {
  return weight * 2 * 0.69314718055994530942 / double(n_params);
}

}  // namespace vnr
