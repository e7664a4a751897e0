#pragma once
// Multi-resolution grid encoding (HashGrid / DenseGrid / TiledGrid) with tiny-cuda-nn's exact
// level table, position transform, indexing and interpolation weights (docs/semantics.md A.2).
// The per-sample functions are single-source (VNR_HD) over a POD layout.
#include <cmath>
#include <cstdint>
#include <type_traits>
#include "vnr/core/half.h"
#include "vnr/hd.h"
#include "vnr/model_config.h"

namespace vnr {

constexpr int kMaxGridLevels = 32;

struct GridLevel {
  float scale = 0;          // scale_l = exp2f(l * log2f(s)) * base - 1
  uint32_t res = 0;         // vertices per axis
  uint32_t n_entries = 0;   // n_l (the modulus)
  uint32_t offset = 0;      // first entry of the level (entries, not floats)
  uint32_t hashed = 0;      // 1 when res^3 > n_l and the grid type is Hash
  uint32_t pow2_mask = 0;   // n_l - 1 when n_l is a power of two, else 0
};

struct GridLayout {
  uint32_t n_levels = 0, n_features = 0;  // L, F
  Interpolation interpolation = Interpolation::Linear;
  uint64_t n_entries = 0;                 // sum of n_l
  GridLevel levels[kMaxGridLevels];
  uint64_t n_params() const { return n_entries * n_features; }
};

// Where a grid's features per level, a runtime count, become the compile-time F of the kernels
// (registers and vector widths): fn(std::integral_constant<int, F>()) for F = 1, 2, 4 or 8 (what tcnn
// supports; configs are checked when parsed), and true; false for any other count. Called once per
// object, where it is made, never per call: the encoding factory (GridEncoding<F>, the CPU), the GPU's
// grid kernels (cuda::grid_kernels) and the GPU renderer's binding of a network (WarpNetworkRef<F>).
// The same counts for code that instantiates per count: X(1) X(2) X(4) X(8).
#define VNR_GRID_FEATURE_COUNTS(X) X(1) X(2) X(4) X(8)
VNR_HD_TEMPLATE
template <typename Fn>
VNR_HD inline bool with_feature_count(uint32_t n_features, Fn&& fn) {
  switch (n_features) {
    case 1: fn(std::integral_constant<int, 1>()); return true;
    case 2: fn(std::integral_constant<int, 2>()); return true;
    case 4: fn(std::integral_constant<int, 4>()); return true;
    case 8: fn(std::integral_constant<int, 8>()); return true;
    default: return false;
  }
}

GridLayout make_grid_layout(const EncodingConfig& cfg);

VNR_HD VNR_INLINE uint32_t grid_entry(const GridLevel& L, uint32_t cx, uint32_t cy, uint32_t cz) {
  uint32_t idx;
  if (L.hashed) idx = cx ^ (cy * 2654435761u) ^ (cz * 805459861u);
  else idx = cx + cy * L.res + cz * (L.res * L.res);  // uint32 wrap, as tcnn
  if (L.pow2_mask) return idx & L.pow2_mask;
  return idx < L.n_entries ? idx : idx % L.n_entries;
}

// Grid parameters are read from the fp32 master copy or from the fp16 working copy (as tcnn's
// forward pass does); both go through this overload set.
VNR_HD VNR_INLINE float grid_param(const float* p) { return *p; }
VNR_HD VNR_INLINE float grid_param(const uint16_t* p) { return half_to_float(*p); }

// Lattice cell, fractional position and the 8 corner (entry, weight) pairs of one level.
struct GridCorners {
  uint32_t entry[8];
  float weight[8];
};

VNR_HD VNR_INLINE float grid_smoothstep(float t) { return t * t * (3.0f - 2.0f * t); }

VNR_HD VNR_INLINE void grid_corners(const GridLevel& L, Interpolation interp, float x, float y, float z,
                                GridCorners& c) {
  float p[3] = {fmaf(L.scale, x, 0.5f), fmaf(L.scale, y, 0.5f), fmaf(L.scale, z, 0.5f)};
  uint32_t i[3];
  float s[3];
  for (int d = 0; d < 3; ++d) {
    float fl = floorf(p[d]);
    i[d] = uint32_t(int32_t(fl));
    float t = p[d] - fl;
    s[d] = interp == Interpolation::Smoothstep ? grid_smoothstep(t) : t;
  }
  for (int k = 0; k < 8; ++k) {
    float w = 1.0f;
    for (int d = 0; d < 3; ++d) w *= ((k >> d) & 1) ? s[d] : 1.0f - s[d];
    c.weight[k] = w;
    c.entry[k] = grid_entry(L, i[0] + (k & 1), i[1] + ((k >> 1) & 1), i[2] + ((k >> 2) & 1));
  }
  if (interp == Interpolation::Nearest) {  // tcnn: the lower corner of the cell, weight 1
    c.weight[0] = 1.0f;
    for (int k = 1; k < 8; ++k) c.weight[k] = 0.0f;
  }
}

// How the F features of one grid entry are read from a table of P: one grid_param() per feature. The
// CUDA backend specialises it for its half table (one vector load per entry, cuda/grid_device.cuh).
template <typename P>
struct GridEntryLoad {
  template <int F>
  VNR_HD VNR_INLINE static void load(const P* entry, float* out) {
    for (int f = 0; f < F; ++f) out[f] = grid_param(entry + f);
  }
};

// Forward of one level for one sample: out[f * stride] = sum_k w_k * theta[(offset + entry_k) * F + f],
// accumulated with FMA in corner order (vnr's binary32 reference, docs/semantics.md A.2.7). Nearest reads
// corner 0 alone; the others' loop has a constant trip count, which keeps the corners in registers on the
// GPU (a runtime bound indexes them in local memory: a load/store queue round trip per corner).
template <int F, typename P>
VNR_HD VNR_INLINE void grid_corner_fma(const GridLevel& L, const P* params, const GridCorners& c, int k, float* acc) {
  float th[F];
  GridEntryLoad<P>::template load<F>(params + (uint64_t(L.offset) + c.entry[k]) * F, th);
  for (int f = 0; f < F; ++f) acc[f] = fmaf(c.weight[k], th[f], acc[f]);
}

template <int F, typename P>
VNR_HD VNR_INLINE void grid_level_forward(const GridLevel& L, Interpolation interp, const P* params, float x,
                                      float y, float z, float* out, int64_t stride) {
  GridCorners c;
  grid_corners(L, interp, x, y, z, c);
  float acc[F];
  for (int f = 0; f < F; ++f) acc[f] = 0.0f;
  if (interp == Interpolation::Nearest) {
    grid_corner_fma<F>(L, params, c, 0, acc);
  } else {
    for (int k = 0; k < 8; ++k) grid_corner_fma<F>(L, params, c, k, acc);
  }
  for (int f = 0; f < F; ++f) out[f * stride] = acc[f];
}

// How a corner's gradient reaches the table: gr[f] = fma(w, g[f], gr[f]) (one thread per level, CPU);
// the CUDA backend adds w * g[f] atomically instead (cuda/grid_device.cuh).
struct GridGradFma {
  template <int F>
  VNR_HD VNR_INLINE void add(float* gr, float w, const float* g) const {
    for (int f = 0; f < F; ++f) gr[f] = fmaf(w, g[f], gr[f]);
  }
};

// Backward of one level for one sample: grad[(offset + entry_k) * F + f] += w_k * dy[f * stride].
// With GridGradFma not thread-safe by itself: the trainer gives each level to exactly one thread.
template <int F, typename Add = GridGradFma>
VNR_HD VNR_INLINE void grid_level_backward(const GridLevel& L, Interpolation interp, float* grad, float x, float y,
                                       float z, const float* dy, int64_t stride, const Add& accumulate = Add()) {
  GridCorners c;
  grid_corners(L, interp, x, y, z, c);
  float g[F];
  for (int f = 0; f < F; ++f) g[f] = dy[f * stride];
  const uint64_t base = uint64_t(L.offset);
  if (interp == Interpolation::Nearest) {  // corner 0 alone, else a constant trip count (grid_level_forward)
    accumulate.template add<F>(grad + (base + c.entry[0]) * F, c.weight[0], g);
  } else {
    for (int k = 0; k < 8; ++k) accumulate.template add<F>(grad + (base + c.entry[k]) * F, c.weight[k], g);
  }
}

// d(feature f of level L)/d(x_d) for one sample (docs/semantics.md A.2.9), written to dydx[f*3 + d].
template <int F, typename P>
VNR_HD VNR_INLINE void grid_level_input_grad(const GridLevel& L, Interpolation interp, const P* params, float x,
                                         float y, float z, float* dydx) {
  for (int f = 0; f < 3 * F; ++f) dydx[f] = 0.0f;
  if (interp == Interpolation::Nearest) return;
  float p[3] = {fmaf(L.scale, x, 0.5f), fmaf(L.scale, y, 0.5f), fmaf(L.scale, z, 0.5f)};
  uint32_t i[3];
  float s[3], ds[3];
  for (int d = 0; d < 3; ++d) {
    float fl = floorf(p[d]);
    i[d] = uint32_t(int32_t(fl));
    float t = p[d] - fl;
    s[d] = interp == Interpolation::Smoothstep ? grid_smoothstep(t) : t;
    ds[d] = interp == Interpolation::Smoothstep ? 6.0f * t * (1.0f - t) : 1.0f;
  }
  for (int k = 0; k < 8; ++k) {
    uint32_t e = grid_entry(L, i[0] + (k & 1), i[1] + ((k >> 1) & 1), i[2] + ((k >> 2) & 1));
    const P* th = params + (uint64_t(L.offset) + e) * F;
    for (int d = 0; d < 3; ++d) {
      float w = L.scale * ds[d] * (((k >> d) & 1) ? 1.0f : -1.0f);
      for (int e2 = 0; e2 < 3; ++e2)
        if (e2 != d) w *= ((k >> e2) & 1) ? s[e2] : 1.0f - s[e2];
      for (int f = 0; f < F; ++f) dydx[f * 3 + d] += w * grid_param(th + f);
    }
  }
}

}  // namespace vnr
