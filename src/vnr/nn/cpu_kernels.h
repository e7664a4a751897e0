#pragma once
// Grid-encoding and optimizer loops of the CPU backend, compiled once per SIMD target (Highway's
// foreach_target) and chosen at run time. The loop bodies are the single-source VNR_HD functions of
// grid_encoding.h; per-target compilation lets the compiler use AVX-512/AVX2 for the feature loops.
#include <cstdint>
#include "vnr/nn/adam_update.h"
#include "vnr/nn/grid_encoding.h"

namespace vnr::kernels {

// The grid loops for F = g.n_features (1, 2, 4 or 8; defined for those only), which GridEncoding<F> fixed
// when the encoding factory made it.
// X0 rows [0, L*F) for n samples (feature-major, stride n), from the fp16 table.
template <int F>
void grid_encode(const GridLayout& g, const uint16_t* table, const float* x, const float* y, const float* z, int n,
                 float* X0);
// grad += dL/dtheta of one level for n samples; dEnc chunked (chunk c at c * in_pad * chunk).
template <int F>
void grid_backward_level(const GridLayout& g, uint32_t level, const float* x, const float* y, const float* z,
                         int64_t n, const float* dEnc, uint32_t in_pad, int chunk, float* grad);
#define VNR_GRID_KERNELS_OF(F)                                                                                 \
  template <>                                                                                                  \
  void grid_encode<F>(const GridLayout&, const uint16_t*, const float*, const float*, const float*, int, float*); \
  template <>                                                                                                  \
  void grid_backward_level<F>(const GridLayout&, uint32_t, const float*, const float*, const float*, int64_t,  \
                              const float*, uint32_t, int, float*);
VNR_GRID_FEATURE_COUNTS(VNR_GRID_KERNELS_OF)
#undef VNR_GRID_KERNELS_OF

// x[i], y[i], z[i] = xyz[3i], xyz[3i + 1], xyz[3i + 2] for i in [0, n) (interleaved points to SoA).
void deinterleave_xyz(const float* xyz, int64_t n, float* x, float* y, float* z);

struct AdamStep : AdamHyper {
  bool matrix;     // true: l2 applies, never skipped; false: skipped where the gradient is 0
  const float* bias_sqrt;  // sqrtf(1 - beta2^c), by c
  const float* bias_den;   // 1 - beta1^c, by c
};
// Updates params/m/v/c in [0, n), zeroes grads, and writes half[i] = fp16(params[i]) when half != nullptr.
void adam_range(const AdamStep& k, float* params, float* grads, float* m, float* v, uint32_t* c, uint16_t* half,
                int64_t n);

}  // namespace vnr::kernels
