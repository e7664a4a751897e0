#include "vnr/core/rng.h"
#include "vnr/cuda/grid_device.cuh"
#include "vnr/cuda/kernels.cuh"
#include "vnr/nn/adam_update.h"
#include "vnr/nn/loss.h"

namespace vnr::cuda {
namespace {

constexpr int kThreads = 256;

// One thread per (point, level), level-major: neighbouring threads read the same level's table.
template <int F>
__global__ void encode_kernel(GridLayout g, const __half* __restrict__ table, Coords c, int64_t n, int in_pad,
                              __half* __restrict__ X0) {
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n * g.n_levels) return;
  const int level = int(i / n);
  const int64_t s = i - int64_t(level) * n;
  float out[F];
  grid_level_forward<F>(g.levels[level], g.interpolation, table, c.x[s * c.stride], c.y[s * c.stride],
                        c.z[s * c.stride], out, 1);
  __half* row = X0 + s * in_pad;
  store_halves<F>(out, row + level * F);
  if (level == 0)
    for (int k = int(g.n_levels * F); k < in_pad; ++k) row[k] = __float2half_rn(0.0f);
}

// One thread per (point, level); a block's threads share a level and the blocks take the levels in turn
// (block b: level b mod L). The coarse levels' few entries take every sample's atomics, serialised in the
// L2 slices that hold them (the paper config's level 0: 64 entries, 16 cache lines, a million vector
// atomics a step); level-major, every SM would queue on those lines at the kernel's start, while in turn
// they are spread over the kernel beside the fine levels' scattered ones.
template <int F>
__global__ void grid_backward_kernel(GridLayout g, Coords c, int64_t n, int in_pad, const __half* __restrict__ dX0,
                                     float inv_scale, float* __restrict__ grad) {
  const int level = int(blockIdx.x % g.n_levels);
  const int64_t s = int64_t(blockIdx.x / g.n_levels) * blockDim.x + threadIdx.x;
  if (s >= n) return;
  float dy[F];
  load_halves<F>(dX0 + s * in_pad + level * F, dy);
  bool any = false;
  for (int f = 0; f < F; ++f) {
    dy[f] *= inv_scale;
    any |= dy[f] != 0.0f;
  }
  if (!any) return;
  grid_level_backward<F>(g.levels[level], g.interpolation, grad, c.x[s * c.stride], c.y[s * c.stride],
                         c.z[s * c.stride], dy, 1, GridGradAtomic());
}

__global__ void sample_kernel(GridView vol, uint64_t seed, uint64_t step, int chunk, int64_t batch, float* x,
                              float* y, float* z, float* target) {
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= batch) return;
  float px, py, pz;
  uniform_sample_coordinate(seed, step, uint64_t(i / chunk), chunk, int(i % chunk), &px, &py, &pz);
  x[i] = px;
  y[i] = py;
  z[i] = pz;
  target[i] = grid_lookup(vol, px, py, pz);
}

__global__ void loss_kernel(LossType t, Activation out_act, const float* __restrict__ out_pre,
                            const float* __restrict__ target, int64_t n, int n_out, int out_pad, float inv_n,
                            __half* __restrict__ dOut, float* loss_slot) {
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  float l = 0.0f;
  if (i < n) {
    for (int o = 0; o < out_pad; ++o) {
      float g = 0.0f;
      if (o < n_out) {
        const float pre = out_pre[i * n_out + o];
        l += loss_value_and_grad(t, activate(out_act, pre), target[i], inv_n, &g);
        g = g * kLossScale * activate_derivative(out_act, pre);
      }
      dOut[i * out_pad + o] = __float2half_rn(g);
    }
  }
  for (int off = 16; off > 0; off /= 2) l += __shfl_down_sync(0xffffffffu, l, off);
  __shared__ float warp_sums[kThreads / 32];
  if (threadIdx.x % 32 == 0) warp_sums[threadIdx.x / 32] = l;
  __syncthreads();
  if (threadIdx.x == 0) {
    float sum = 0.0f;
    for (int w = 0; w < int(blockDim.x / 32); ++w) sum += warp_sums[w];
    atomicAdd(loss_slot, sum);
  }
}

// adam_update() (nn/adam_update.h), the CPU's update, kAdamPerThread parameters per thread with each
// round of loads issued before any arithmetic: one parameter per thread leaves each warp waiting on
// dependent memory round trips (gradient, state, bias tables). Lazy Adam skips grid parameters whose
// gradient is 0; their state is not even read (a grid entry of 8 features is one 32-byte sector, so an
// entry no sample touched costs a step one read of its gradient).
constexpr int kAdamPerThread = 4;

__global__ void adam_kernel(AdamArgs a, float* __restrict__ w, float* __restrict__ grads, float* __restrict__ m,
                            float* __restrict__ v, uint32_t* __restrict__ c, __half* __restrict__ half_out, int64_t n,
                            const float* __restrict__ bias_sqrt, const float* __restrict__ bias_den) {
  const int64_t first = int64_t(blockIdx.x) * blockDim.x * kAdamPerThread + threadIdx.x;
  float g[kAdamPerThread], wi[kAdamPerThread], mi[kAdamPerThread], vi[kAdamPerThread];
  float bs[kAdamPerThread], bd[kAdamPerThread];
  uint32_t ci[kAdamPerThread];
  bool live[kAdamPerThread];
#pragma unroll
  for (int j = 0; j < kAdamPerThread; ++j) {
    const int64_t i = first + int64_t(j) * blockDim.x;
    g[j] = i < n ? grads[i] : 0.0f;
  }
#pragma unroll
  for (int j = 0; j < kAdamPerThread; ++j) {
    const int64_t i = first + int64_t(j) * blockDim.x;
    live[j] = i < n && (a.matrix || g[j] != 0.0f);
    if (live[j]) {
      wi[j] = w[i];
      mi[j] = m[i];
      vi[j] = v[i];
      ci[j] = c[i] + 1;
    }
  }
#pragma unroll
  for (int j = 0; j < kAdamPerThread; ++j) {
    const int64_t i = first + int64_t(j) * blockDim.x;
    if (live[j]) {
      grads[i] = 0.0f;  // the others' gradient is 0 already
      bs[j] = bias_sqrt[ci[j]];
      bd[j] = bias_den[ci[j]];
    }
  }
#pragma unroll
  for (int j = 0; j < kAdamPerThread; ++j) {
    const int64_t i = first + int64_t(j) * blockDim.x;
    if (!live[j]) continue;
    float wn = wi[j], mn = mi[j], vn = vi[j];
    adam_update(a, a.matrix != 0, g[j], bs[j], bd[j], wn, mn, vn);
    w[i] = wn;
    m[i] = mn;
    v[i] = vn;
    c[i] = ci[j];
    half_out[i] = __float2half_rn(wn);
  }
}

__global__ void voxel_centres_kernel(Int3 dims, int64_t first, int64_t count, int64_t padded, float* xyz) {
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= padded) return;
  voxel_centre(dims, first + (i < count ? i : count - 1), &xyz[3 * i], &xyz[3 * i + 1], &xyz[3 * i + 2]);
}

}  // namespace

template <int F>
void encode_launch(const GridLayout& g, const __half* table, Coords c, int64_t n, int in_pad, __half* X0,
                   cudaStream_t s) {
  const int64_t total = n * g.n_levels;
  if (total <= 0) return;
  encode_kernel<F><<<blocks_for(total, kThreads), kThreads, 0, s>>>(g, table, c, n, in_pad, X0);
  VNR_CUDA_LAUNCHED();
}

template <int F>
void grid_backward_launch(const GridLayout& g, Coords c, int64_t n, int in_pad, const __half* dX0, float* grad,
                          cudaStream_t s) {
  if (n <= 0 || g.n_levels == 0) return;
  const float inv = 1.0f / kLossScale;
  const unsigned blocks = blocks_for(n, kThreads) * g.n_levels;  // each level's samples in blocks of kThreads
  grid_backward_kernel<F><<<blocks, kThreads, 0, s>>>(g, c, n, in_pad, dX0, inv, grad);
  VNR_CUDA_LAUNCHED();
}

GridKernels grid_kernels(const GridLayout& g) {
  GridKernels k;
  if (!with_feature_count(g.n_features, [&](auto F) {
        k.encode = &encode_launch<F()>;
        k.backward = &grid_backward_launch<F()>;
      }))
    cuda_fail_message("grid encoding: n_features_per_level must be 1, 2, 4 or 8");
  return k;
}

void sample_in_core(GridView volume, uint64_t seed, uint64_t step, int chunk, int64_t batch, float* x, float* y,
                    float* z, float* target, cudaStream_t s) {
  sample_kernel<<<blocks_for(batch, kThreads), kThreads, 0, s>>>(volume, seed, step, chunk, batch, x, y, z, target);
  VNR_CUDA_LAUNCHED();
}

void loss_and_grad(LossType t, Activation out_act, const float* out_pre, const float* target, int64_t n, int n_out,
                   int out_pad, float inv_n, __half* dOut, float* loss_slot, cudaStream_t s) {
  loss_kernel<<<blocks_for(n, kThreads), kThreads, 0, s>>>(t, out_act, out_pre, target, n, n_out, out_pad, inv_n,
                                                           dOut, loss_slot);
  VNR_CUDA_LAUNCHED();
}

void adam(const AdamArgs& a, float* w, float* grads, float* m, float* v, uint32_t* c, __half* half_out, int64_t n,
          const float* bias_sqrt, const float* bias_den, cudaStream_t s) {
  if (n <= 0) return;
  adam_kernel<<<blocks_for(n, kThreads * kAdamPerThread), kThreads, 0, s>>>(a, w, grads, m, v, c, half_out, n,
                                                                          bias_sqrt, bias_den);
  VNR_CUDA_LAUNCHED();
}

void voxel_centres(Int3 dims, int64_t first, int64_t count, int64_t padded, float* xyz, cudaStream_t s) {
  if (padded <= 0) return;
  voxel_centres_kernel<<<blocks_for(padded, kThreads), kThreads, 0, s>>>(dims, first, count, padded, xyz);
  VNR_CUDA_LAUNCHED();
}

// ------------------------------------------------------------------------------------------------
// Macro-cell value ranges

RangeGridDims range_grid_dims(const ValueRangeGrid& g) {
  return RangeGridDims{int32_t(g.cells.x),       int32_t(g.cells.y),       int32_t(g.cells.z),
                       g.cell_size,              float(g.volume_dims.x),   float(g.volume_dims.y),
                       float(g.volume_dims.z)};
}

namespace {

__global__ void ranges_from_grid_kernel(GridView vol, RangeGridDims r, float* __restrict__ lo,
                                        float* __restrict__ hi) {
  const int64_t c = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (c >= int64_t(r.nx) * r.ny * r.nz) return;
  const int32_t cx = int32_t(c % r.nx), cy = int32_t((c / r.nx) % r.ny), cz = int32_t(c / (int64_t(r.nx) * r.ny));
  cell_value_range(vol, r.cell_size, cx, cy, cz, &lo[c], &hi[c]);
}

// Float min/max through the integer order of the bit patterns (non-negative floats order as ints,
// negative ones reversed as unsigned). -0 is made +0 first: the patterns of the two zeros do not order.
__device__ inline void atomic_min_float(float* a, float v) {
  if (v >= 0.0f) atomicMin(reinterpret_cast<int*>(a), __float_as_int(v));
  else atomicMax(reinterpret_cast<unsigned*>(a), __float_as_uint(v));
}
__device__ inline void atomic_max_float(float* a, float v) {
  if (v >= 0.0f) atomicMax(reinterpret_cast<int*>(a), __float_as_int(v));
  else atomicMin(reinterpret_cast<unsigned*>(a), __float_as_uint(v));
}

__global__ void ranges_add_kernel(RangeGridDims r, const float* __restrict__ x, const float* __restrict__ y,
                                  const float* __restrict__ z, const float* __restrict__ v, int64_t n,
                                  float* __restrict__ lo, float* __restrict__ hi) {
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const float inv = 1.0f / float(r.cell_size);
  int32_t c0[3], c1[3];
  value_range_cells(x[i] * r.sx, inv, r.nx, &c0[0], &c1[0]);
  value_range_cells(y[i] * r.sy, inv, r.ny, &c0[1], &c1[1]);
  value_range_cells(z[i] * r.sz, inv, r.nz, &c0[2], &c1[2]);
  const float val = v[i] + 0.0f;  // -0 -> +0
  if (val != val) return;         // NaN: ignored (the CPU's min/max keep the old value too)
  for (int32_t cz = c0[2]; cz <= c1[2]; ++cz)
    for (int32_t cy = c0[1]; cy <= c1[1]; ++cy)
      for (int32_t cx = c0[0]; cx <= c1[0]; ++cx) {
        const int64_t c = cx + int64_t(r.nx) * (cy + int64_t(r.ny) * cz);
        atomic_min_float(&lo[c], val);
        atomic_max_float(&hi[c], val);
      }
}

__global__ void ranges_clear_kernel(int64_t n, float* __restrict__ lo, float* __restrict__ hi) {
  const int64_t c = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (c >= n) return;
  lo[c] = INFINITY;
  hi[c] = -INFINITY;
}

}  // namespace

void ranges_from_grid(GridView volume, const RangeGridDims& r, float* lo, float* hi, cudaStream_t s) {
  const int64_t n = int64_t(r.nx) * r.ny * r.nz;
  ranges_from_grid_kernel<<<blocks_for(n, 64), 64, 0, s>>>(volume, r, lo, hi);
  VNR_CUDA_LAUNCHED();
}

void ranges_add_samples(const RangeGridDims& r, const float* x, const float* y, const float* z, const float* v,
                        int64_t n, float* lo, float* hi, cudaStream_t s) {
  if (n <= 0) return;
  ranges_add_kernel<<<blocks_for(n, kThreads), kThreads, 0, s>>>(r, x, y, z, v, n, lo, hi);
  VNR_CUDA_LAUNCHED();
}

void ranges_clear(const RangeGridDims& r, float* lo, float* hi, cudaStream_t s) {
  const int64_t n = int64_t(r.nx) * r.ny * r.nz;
  ranges_clear_kernel<<<blocks_for(n, kThreads), kThreads, 0, s>>>(n, lo, hi);
  VNR_CUDA_LAUNCHED();
}

}  // namespace vnr::cuda
