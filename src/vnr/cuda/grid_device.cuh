#pragma once
// The CUDA layer under grid_encoding.h's shared level code (CUDA-only header): an entry's F half features
// read or written as one vector access (GridEntryLoad<__half>) and the vector atomics of the backward
// (GridGradAtomic); the level forward/backward themselves are grid_encoding.h's.
#include <cuda_fp16.h>
#include <type_traits>
#include "vnr/nn/grid_encoding.h"

namespace vnr::cuda {

// A grid entry's F features as one vector access (F = 2: 32 bits, 4: 64, 8: 128) instead of F 16-bit
// ones: the encoder and its backward are bound by the load/store queue, not by bandwidth. Entries are
// F-aligned: the table starts after the MLP weights, a multiple of 256 halves.
template <int F>
__device__ __forceinline__ void load_halves(const __half* __restrict__ p, float* out) {
  if constexpr (F == 1) {
    out[0] = __half2float(__ldg(p));
  } else if constexpr (F == 2) {
    const float2 v = __half22float2(__ldg(reinterpret_cast<const __half2*>(p)));
    out[0] = v.x;
    out[1] = v.y;
  } else {
    using Vec = std::conditional_t<F == 4, uint2, uint4>;
    const Vec raw = __ldg(reinterpret_cast<const Vec*>(p));
    const __half2* h = reinterpret_cast<const __half2*>(&raw);
    for (int j = 0; j < F / 2; ++j) {
      const float2 v = __half22float2(h[j]);
      out[2 * j] = v.x;
      out[2 * j + 1] = v.y;
    }
  }
}

template <int F>
__device__ __forceinline__ void store_halves(const float* in, __half* p) {
  if constexpr (F == 1) {
    p[0] = __float2half_rn(in[0]);
  } else {
    alignas(16) __half2 h[F / 2];  // read below as one vector (aligned should it ever live in memory)
    for (int j = 0; j < F / 2; ++j) h[j] = __floats2half2_rn(in[2 * j], in[2 * j + 1]);
    if constexpr (F == 2) *reinterpret_cast<__half2*>(p) = h[0];
    else if constexpr (F == 4) *reinterpret_cast<uint2*>(p) = *reinterpret_cast<const uint2*>(h);
    else *reinterpret_cast<uint4*>(p) = *reinterpret_cast<const uint4*>(h);
  }
}

// grad[0, F) += v: vector atomics on sm_90 (float2 / float4 atomicAdd), F scalar ones before it.
template <int F>
__device__ __forceinline__ void atomic_add_entry(float* gr, const float* v) {
#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 900
  if constexpr (F == 2) {
    atomicAdd(reinterpret_cast<float2*>(gr), make_float2(v[0], v[1]));
  } else if constexpr (F % 4 == 0) {
    for (int f = 0; f < F; f += 4)
      atomicAdd(reinterpret_cast<float4*>(gr + f), make_float4(v[f], v[f + 1], v[f + 2], v[f + 3]));
  } else
#endif
  {
    for (int f = 0; f < F; ++f) atomicAdd(gr + f, v[f]);
  }
}

// The shared level code with this header's accesses: grid_level_forward<F> over the half table (one
// vector load per corner) and grid_level_backward<F, GridGradAtomic> (vector atomics).
// (Host passes of nvcc see plain loads and adds: the shared functions are __host__ __device__.)
struct GridGradAtomic {
  template <int F>
  VNR_HD VNR_INLINE void add(float* gr, float w, const float* g) const {
    float v[F];
    for (int f = 0; f < F; ++f) v[f] = w * g[f];
#ifdef __CUDA_ARCH__
    atomic_add_entry<F>(gr, v);
#else
    for (int f = 0; f < F; ++f) gr[f] += v[f];
#endif
  }
};

}  // namespace vnr::cuda

namespace vnr {
template <>
struct GridEntryLoad<__half> {
  template <int F>
  VNR_HD VNR_INLINE static void load(const __half* entry, float* out) {
#ifdef __CUDA_ARCH__
    vnr::cuda::load_halves<F>(entry, out);
#else
    for (int f = 0; f < F; ++f) out[f] = __half2float(entry[f]);
#endif
  }
};
}  // namespace vnr
