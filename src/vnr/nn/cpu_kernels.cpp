// Per-target compilation of the grid and Adam loops (see cpu_kernels.h).
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "vnr/nn/cpu_kernels.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

#include <cmath>
#include "vnr/nn/cpu_kernels.h"

HWY_BEFORE_NAMESPACE();
namespace vnr::kernels {
namespace HWY_NAMESPACE {

template <int F>
void EncodeF(const GridLayout& g, const float* table, const float* x, const float* y, const float* z, int n,
             float* X0) {
  for (uint32_t l = 0; l < g.n_levels; ++l) {
    const GridLevel L = g.levels[l];
    float* out = X0 + size_t(l) * F * n;
    for (int s = 0; s < n; ++s) grid_level_forward<F>(L, g.interpolation, table, x[s], y[s], z[s], out + s, n);
  }
}

void GridEncode(const GridLayout& g, const float* table, const float* x, const float* y, const float* z, int n,
                float* X0) {
  switch (g.n_features) {
    case 1: EncodeF<1>(g, table, x, y, z, n, X0); break;
    case 2: EncodeF<2>(g, table, x, y, z, n, X0); break;
    case 4: EncodeF<4>(g, table, x, y, z, n, X0); break;
    case 8: EncodeF<8>(g, table, x, y, z, n, X0); break;
  }
}

template <int F>
void BackwardF(const GridLayout& g, uint32_t l, const float* x, const float* y, const float* z, int64_t n,
               const float* dEnc, uint32_t in_pad, int chunk, float* grad) {
  const GridLevel L = g.levels[l];
  for (int64_t c0 = 0; c0 < n; c0 += chunk) {
    const float* dy = dEnc + (c0 / chunk) * int64_t(in_pad) * chunk + int64_t(l) * F * chunk;
    const int64_t m = n - c0 < chunk ? n - c0 : chunk;
    for (int64_t s = 0; s < m; ++s)
      grid_level_backward<F>(L, g.interpolation, grad, x[c0 + s], y[c0 + s], z[c0 + s], dy + s, chunk);
  }
}

void GridBackwardLevel(const GridLayout& g, uint32_t level, const float* x, const float* y, const float* z,
                       int64_t n, const float* dEnc, uint32_t in_pad, int chunk, float* grad) {
  switch (g.n_features) {
    case 1: BackwardF<1>(g, level, x, y, z, n, dEnc, in_pad, chunk, grad); break;
    case 2: BackwardF<2>(g, level, x, y, z, n, dEnc, in_pad, chunk, grad); break;
    case 4: BackwardF<4>(g, level, x, y, z, n, dEnc, in_pad, chunk, grad); break;
    case 8: BackwardF<8>(g, level, x, y, z, n, dEnc, in_pad, chunk, grad); break;
  }
}

// tcnn's Adam element update (compat.md A.7.1), written branch-light so the compiler can vectorise
// it: the skip is a select, not a jump.
void AdamRange(const AdamStep& k, float* HWY_RESTRICT w, float* HWY_RESTRICT grads, float* HWY_RESTRICT m,
               float* HWY_RESTRICT v, uint32_t* HWY_RESTRICT c, int64_t n) {
  for (int64_t i = 0; i < n; ++i) {
    float g = grads[i];
    grads[i] = 0.0f;
    const bool active = k.matrix || g != 0.0f;
    float wi = w[i];
    if (k.matrix) g += k.l2 * wi;
    const float mi = k.beta1 * m[i] + (1.0f - k.beta1) * g;
    const float vi = k.beta2 * v[i] + (1.0f - k.beta2) * g * g;
    const uint32_t ci = c[i] + 1;
    const float lr_t = k.lr * k.bias_sqrt[active ? ci : 0] / k.bias_den[active ? ci : 1];
    float eff = lr_t / (std::sqrt(vi) + k.eps);
    eff = eff < k.lo ? k.lo : (eff > k.hi ? k.hi : eff);
    const float wd = (1.0f - k.rel * lr_t) * wi - std::copysign(k.abs_decay * lr_t, wi);
    const float wn = wd - eff * mi;
    w[i] = active ? wn : wi;
    m[i] = active ? mi : m[i];
    v[i] = active ? vi : v[i];
    c[i] = active ? ci : c[i];
  }
}

}  // namespace HWY_NAMESPACE
}  // namespace vnr::kernels
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace vnr::kernels {
HWY_EXPORT(GridEncode);
HWY_EXPORT(GridBackwardLevel);
HWY_EXPORT(AdamRange);

void grid_encode(const GridLayout& g, const float* table, const float* x, const float* y, const float* z, int n,
                 float* X0) {
  HWY_DYNAMIC_DISPATCH(GridEncode)(g, table, x, y, z, n, X0);
}
void grid_backward_level(const GridLayout& g, uint32_t level, const float* x, const float* y, const float* z,
                         int64_t n, const float* dEnc, uint32_t in_pad, int chunk, float* grad) {
  HWY_DYNAMIC_DISPATCH(GridBackwardLevel)(g, level, x, y, z, n, dEnc, in_pad, chunk, grad);
}
void adam_range(const AdamStep& k, float* params, float* grads, float* m, float* v, uint32_t* c, int64_t n) {
  HWY_DYNAMIC_DISPATCH(AdamRange)(k, params, grads, m, v, c, n);
}
}  // namespace vnr::kernels
#endif
