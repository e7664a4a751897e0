#pragma once
#include <cmath>
#include <cstring>
#include "vnr/hd.h"
#include "vnr/model_config.h"

namespace vnr {

// Loss value and gradient for one output element (docs/semantics.md A.6), with the mean's 1/N folded in.
// The loss scale S cancels exactly in binary32 and is 1 on the CPU.
VNR_HD inline float loss_value_and_grad(LossType t, float pred, float target, float inv_n, float* grad) {
  float d = pred - target;
  switch (t) {
    case LossType::L1:
      *grad = copysignf(1.0f, d) * inv_n;  // d = +0 gives +1, as tcnn
      return fabsf(d) * inv_n;
    case LossType::L2:
      *grad = 2.0f * d * inv_n;
      return d * d * inv_n;
    case LossType::RelativeL2: {
      float den = pred * pred + 0.01f;  // treated as a constant in the gradient
      *grad = 2.0f * d / den * inv_n;
      return d * d / den * inv_n;
    }
    case LossType::RelativeL1: {
      float den = fabsf(pred) + 0.01f;
      *grad = copysignf(1.0f / den, d) * inv_n;
      return fabsf(d) / den * inv_n;
    }
  }
  *grad = 0;
  return 0;
}

// Output activations (docs/semantics.md A.4.1) and their derivative with respect to the pre-activation.
constexpr float kActivationK = 10.0f;

VNR_HD inline float activate(Activation a, float x) {
  switch (a) {
    case Activation::None: return x;
    case Activation::ReLU: return x > 0 ? x : 0.0f;
    case Activation::Exponential: return expf(x);
    case Activation::Sine: return sinf(x);
    case Activation::Sigmoid: return 1.0f / (1.0f + expf(-x));
    case Activation::Squareplus: {
      float kx = kActivationK * x;
      return 0.5f * (kx + sqrtf(kx * kx + 4.0f)) / kActivationK;
    }
    case Activation::Softplus: return logf(1.0f + expf(kActivationK * x)) / kActivationK;
  }
  return x;
}

// activate() of n values (y may be x), the activation chosen once: a switch per element would cost
// more than a small config's whole output layer.
template <Activation kAct>
inline void activate_n_of(const float* x, int64_t n, float* y) {
  for (int64_t i = 0; i < n; ++i) y[i] = activate(kAct, x[i]);
}
inline void activate_n(Activation a, const float* x, int64_t n, float* y) {
  switch (a) {
    case Activation::None:
      if (y != x) std::memcpy(y, x, sizeof(float) * size_t(n));
      return;
    case Activation::ReLU: return activate_n_of<Activation::ReLU>(x, n, y);
    case Activation::Exponential: return activate_n_of<Activation::Exponential>(x, n, y);
    case Activation::Sine: return activate_n_of<Activation::Sine>(x, n, y);
    case Activation::Sigmoid: return activate_n_of<Activation::Sigmoid>(x, n, y);
    case Activation::Squareplus: return activate_n_of<Activation::Squareplus>(x, n, y);
    case Activation::Softplus: return activate_n_of<Activation::Softplus>(x, n, y);
  }
}

VNR_HD inline float activate_derivative(Activation a, float x) {
  switch (a) {
    case Activation::None: return 1.0f;
    case Activation::ReLU: return x > 0 ? 1.0f : 0.0f;
    case Activation::Exponential: return expf(x);
    case Activation::Sine: return cosf(x);
    case Activation::Sigmoid: {
      float y = 1.0f / (1.0f + expf(-x));
      return y * (1.0f - y);
    }
    case Activation::Squareplus: {
      float kx = kActivationK * x;
      return 0.5f * (1.0f + kx / sqrtf(kx * kx + 4.0f));
    }
    case Activation::Softplus: return 1.0f / (1.0f + expf(-kActivationK * x));
  }
  return 1.0f;
}

}  // namespace vnr
