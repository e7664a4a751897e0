#pragma once
// In-shader network evaluation on the GPU (CUDA-only header), the counterpart of nn/point_eval on the
// CPU: the field value of one point per lane, evaluated warp-cooperatively (the paper's appendix
// "In-Shader Inference Details"). Each lane encodes its point into its row of the warp's 32-row
// activation tile (grid_level_forward over the half table per level, the encode kernel's values); the
// warp multiplies the two 16-row halves by each weight matrix with WMMA 16x16x16 (half in, binary32
// accumulate, ReLU, rounded to half: the fused kernels' arithmetic), skipping a half whose lanes are
// all idle.
#include <mma.h>
#include <cuda_fp16.h>
#include <string>
#include "vnr/cuda/common.h"
#include "vnr/cuda/grid_device.cuh"
#include "vnr/cuda/mlp.cuh"
#include "vnr/cuda/network.cuh"
#include "vnr/nn/loss.h"

namespace vnr::cuda {

constexpr unsigned kFullWarp = 0xffffffffu;

// The grid encoding of one point into one row of halves (one thread doing every level), pad columns
// zeroed; F = g.n_features, fixed when the renderer bound the network (WarpNetworkRef<F>). A level's F
// halves are one vector store (rows are 16-byte aligned: WarpNetwork::ld is a multiple of 8): shared
// memory is the in-shader kernels' busiest unit.
template <int F>
__device__ inline void encode_row(const GridLayout& g, const __half* table, float x, float y, float z, __half* row,
                                  int in_pad) {
  const int L = int(g.n_levels);
  for (int l = 0; l < L; ++l) {
    float out[F];
    grid_level_forward<F>(g.levels[l], g.interpolation, table, x, y, z, out, 1);
    store_halves<F>(out, row + l * F);
  }
  for (int k = L * F; k < in_pad; ++k) row[k] = __float2half_rn(0.0f);
}

// A network as the in-shader kernels evaluate it: kept in GPU memory (WarpNetworkRef below), bound
// per block to its shared memory.
struct WarpNetwork {
  GridLayout grid;
  const __half* table;    // half grid parameters
  const __half* weights;  // half MLP weights in GPU memory (tcnn order)
  MlpDims d;
  int out_act;
  int ld;                 // row stride of the activation tiles, halves
  uint32_t n_weights;     // halves
  int stage;              // 1: the weights are copied to shared memory
  int warps_per_block;

  // Shared memory per block: the staged weights, then per warp two 32-row tiles and a 16x16 binary32 tile.
  __host__ __device__ size_t weight_bytes() const { return stage ? (size_t(n_weights) * 2 + 127) / 128 * 128 : 0; }
  __host__ __device__ size_t warp_bytes() const { return size_t(2) * 32 * ld * 2 + 256 * 4; }
  __host__ __device__ size_t smem_bytes() const { return weight_bytes() + size_t(warps_per_block) * warp_bytes(); }

  // One lane's view, bound to its warp's tiles: a lane evaluator of render/inshader_loop.h, for a grid of
  // NF features per level.
  template <int NF>
  struct Eval {
    const WarpNetwork* F;
    const __half* w;
    __half *a0, *a1;
    float* f;
    int lane;

    __device__ bool any(bool active) const { return __any_sync(kFullWarp, active); }
    __device__ float operator()(bool active, float x, float y, float z) const;
  };
};

// The weights' matrices over the warp's two 16-row tiles; the lane's output (before the output activation).
__device__ inline float warp_mlp(const WarpNetwork& F, const __half* w, __half* a0, __half* a1, float* f, int lane,
                                 unsigned act) {
  namespace wmma = nvcuda::wmma;
  const MlpDims& d = F.d;
  const int ld = F.ld;
  float result = 0.0f;
  for (int t = 0; t < 2; ++t) {
    if (((act >> (16 * t)) & 0xffffu) == 0) continue;  // warp-uniform
    __half* in = a0 + t * 16 * ld;
    __half* out = a1 + t * 16 * ld;
    for (int m = 0; m < d.n_matrices; ++m) {
      const int rows = d.rows[m], cols = d.cols[m];
      const bool last = m == d.n_matrices - 1;
      const __half* wm = w + d.offset[m];
      const int nbs = last ? 1 : rows / 16;  // the output layer: the first 16 outputs hold the one we need
      for (int nb = 0; nb < nbs; ++nb) {
        wmma::fragment<wmma::accumulator, 16, 16, 16, float> acc;
        wmma::fill_fragment(acc, 0.0f);
        for (int kb = 0; kb < cols / 16; ++kb) {
          wmma::fragment<wmma::matrix_a, 16, 16, 16, __half, wmma::row_major> a;
          wmma::fragment<wmma::matrix_b, 16, 16, 16, __half, wmma::col_major> b;  // (k, j) = W[j][k]
          wmma::load_matrix_sync(a, in + kb * 16, ld);
          wmma::load_matrix_sync(b, wm + nb * 16 * cols + kb * 16, cols);
          wmma::mma_sync(acc, a, b, acc);
        }
        if (!last)
          for (int i = 0; i < acc.num_elements; ++i) acc.x[i] = acc.x[i] > 0.0f ? acc.x[i] : 0.0f;
        wmma::store_matrix_sync(f, acc, 16, wmma::mem_row_major);
        __syncwarp();
        if (last) {
          if ((lane >> 4) == t) result = f[(lane & 15) * 16];
        } else {  // lane: 8 consecutive values of row lane / 2, two 16-byte loads and one 16-byte store
          const int r = lane >> 1, c = (lane & 1) * 8;
          const float4 lo = *reinterpret_cast<const float4*>(f + r * 16 + c);
          const float4 hi = *reinterpret_cast<const float4*>(f + r * 16 + c + 4);
          const float v[8] = {lo.x, lo.y, lo.z, lo.w, hi.x, hi.y, hi.z, hi.w};
          store_halves<8>(v, out + r * ld + nb * 16 + c);
        }
        __syncwarp();
      }
      __half* tmp = in;
      in = out;
      out = tmp;
    }
  }
  return result;
}

template <int NF>
__device__ inline float WarpNetwork::Eval<NF>::operator()(bool active, float x, float y, float z) const {
  const unsigned act = __ballot_sync(kFullWarp, active);
  if (act == 0) return 0.0f;
  if (active) encode_row<NF>(F->grid, F->table, x, y, z, a0 + lane * F->ld, F->d.in_pad);
  __syncwarp();
  return activate(Activation(F->out_act), warp_mlp(*F, w, a0, a1, f, lane, act));
}

// What the in-shader kernels take for a network: the WarpNetwork in GPU memory (read through the cache,
// warp-uniform), not a kernel-parameter copy that dynamic indexing would move to local memory. bind()
// runs once per thread at the start of a kernel (all threads of the block: it stages the weights). NF: the
// grid's features per level, a template so that no sample asks for it.
template <int NF>
struct WarpNetworkRef {
  const WarpNetwork* F;
  using Eval = WarpNetwork::Eval<NF>;
  __device__ Eval bind(unsigned char* smem) const {
    const WarpNetwork& f = *F;
    const int ld = f.ld;
    Eval e;
    e.F = F;
    e.lane = int(threadIdx.x % 32);
    const int warp = int(threadIdx.x / 32);
    unsigned char* base = smem + f.weight_bytes() + size_t(warp) * f.warp_bytes();
    e.a0 = reinterpret_cast<__half*>(base);
    e.a1 = e.a0 + 32 * ld;
    e.f = reinterpret_cast<float*>(e.a1 + 32 * ld);
    // zero the tiles: idle lanes' rows then hold finite values
    for (int i = e.lane; i < 2 * 32 * ld; i += 32) e.a0[i] = __float2half_rn(0.0f);
    if (f.stage) {
      __half* ws = reinterpret_cast<__half*>(smem);
      const uint4* src = reinterpret_cast<const uint4*>(f.weights);
      uint4* dst = reinterpret_cast<uint4*>(ws);
      for (uint32_t i = threadIdx.x; i < f.n_weights / 8; i += blockDim.x) dst[i] = src[i];
      e.w = ws;
    } else {
      e.w = f.weights;
    }
    __syncthreads();
    return e;
  }
};

// The WarpNetwork of a network on the GPU for blocks of `warps_per_block` warps: the weights staged in
// shared memory when the device's opt-in shared memory holds them, else read through L1.
inline WarpNetwork make_warp_network(const DeviceNetwork& dnet, int warps_per_block) {
  const Network& net = dnet.network();
  const MlpDims& d = dnet.dims();
  if (!mlp_in_16_wide_tiles(net.mlp()))
    cuda_fail_message("in-shader rendering on the GPU multiplies 16 x 16 tiles: this network's padded input (" +
                      std::to_string(d.in_pad) + ") and hidden width (" + std::to_string(d.width) +
                      ") must be multiples of 16; use --strategy streaming");
  WarpNetwork f{};
  f.grid = net.grid();
  f.weights = dnet.half_params();
  f.table = dnet.half_params() + net.mlp().n_params;
  f.d = d;
  f.out_act = int(net.config().network.output_activation);
  f.ld = (d.in_pad > d.width ? d.in_pad : d.width) + 8;  // +8 halves: fewer shared-memory bank conflicts
  f.n_weights = uint32_t(net.mlp().n_params);
  f.warps_per_block = warps_per_block;
  int dev = 0, optin = 0;
  VNR_CUDA_CHECK(cudaGetDevice(&dev));
  VNR_CUDA_CHECK(cudaDeviceGetAttribute(&optin, cudaDevAttrMaxSharedMemoryPerBlockOptin, dev));
  f.stage = 1;
  if (f.smem_bytes() > size_t(optin)) f.stage = 0;  // weights through L1 instead
  if (f.smem_bytes() > size_t(optin))
    cuda_fail_message("in-shader inference: the MLP's activation tiles need " + std::to_string(f.smem_bytes()) +
                      " bytes of shared memory per block, the device has " + std::to_string(optin));
  return f;
}

}  // namespace vnr::cuda
