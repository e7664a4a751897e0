// The GPU MLP: fully fused tensor-core kernels for widths 16/32/64/128 and a cuBLAS path for any width.
//
// Fused kernels (the CUDA counterpart of tcnn's FullyFusedMLP, our own design): a block of 4 or 8
// warps (fused_warps); each warp owns a tile of 16 samples whose activations stay in shared memory from
// the encoding to the output. Layer by layer the block loads one weight matrix into shared memory, then every warp
// multiplies its tile by it with WMMA 16x16x16 half fragments and binary32 accumulators, applies the
// ReLU to the accumulators and rounds to half. Training stores each layer's half activations (the
// backward mask and the weight-gradient GEMM's input); the backward kernel walks the layers in reverse
// the same way. Weight gradients, a reduction over the whole batch, are one cuBLAS GEMM per matrix
// (half inputs, binary32 accumulation and result), on either path.
#include <mma.h>
#include <type_traits>
#include "vnr/cuda/cuda.h"
#include "vnr/cuda/mlp.cuh"
#include "vnr/nn/loss.h"

namespace vnr::cuda {
using namespace nvcuda;

MlpDims mlp_dims(const MlpLayout& m) {
  MlpDims d;
  d.in_pad = int(m.in_pad);
  d.width = int(m.width);
  d.n_matrices = int(m.n_matrices);
  d.n_out = int(m.n_out);
  d.out_pad = int(m.out_pad);
  for (uint32_t i = 0; i < m.n_matrices; ++i) {
    d.rows[i] = int(m.rows[i]);
    d.cols[i] = int(m.cols[i]);
    d.offset[i] = uint32_t(m.offset[i]);
  }
  return d;
}

namespace {

constexpr int kMaxWarps = 8;  // warps per block at most; each owns 16 samples

// Warps per block of the fused kernels. Every block loads each weight matrix into shared memory, so more
// warps share a load. That pays from width 64 on; narrow networks have little to share and keep 4
// (docs/benchmarks.md "History", GPU).
inline int fused_warps(const MlpDims& d) { return d.width >= 64 ? 8 : 4; }

constexpr int kSkew = 8;   // halves of padding per shared-memory row (bank conflicts); ldm stays a multiple of 8

__host__ __device__ inline int fused_ld(const MlpDims& d) { return (d.in_pad > d.width ? d.in_pad : d.width) + kSkew; }

// Shared memory: one weight matrix (at most width rows, since out_pad <= width), two activation tiles
// per warp (ping-pong), and a 16x16 binary32 tile per warp to read accumulators element by element.
size_t fused_smem_bytes(const MlpDims& d) {
  const size_t ld = size_t(fused_ld(d));
  const size_t nw = size_t(fused_warps(d));
  return size_t(d.width) * ld * 2 + nw * 2 * 16 * ld * 2 + nw * 256 * 4;
}


// Copies a rows x cols row-major half matrix into shared memory with row stride ld (16-byte vectors).
__device__ inline void load_rows(__half* dst, int ld, const __half* src, int rows, int cols, int tid, int nthreads) {
  const int vec_per_row = cols / 8;
  for (int i = tid; i < rows * vec_per_row; i += nthreads) {
    const int r = i / vec_per_row, c = i % vec_per_row;
    *reinterpret_cast<uint4*>(dst + r * ld + c * 8) = *reinterpret_cast<const uint4*>(src + size_t(r) * cols + c * 8);
  }
}

// One warp's view of a fused kernel: its 16 samples [s0, s0 + 16), the shared weight matrix, its
// activation tiles (a_in read, a_out written, swapped per layer) and its binary32 scratch tile.
struct FusedTile {
  __half* w;
  __half* a_in;
  __half* a_out;
  float* f;
  int ld, lane;
  int64_t s0;
  bool active;  // the warp has samples (n is a multiple of 16, the grid's last block may have fewer)
};

// Lays out shared memory and loads the warp's first tile: 16 rows of `cols` halves from src (row stride cols).
__device__ inline FusedTile fused_begin(unsigned char* smem, const MlpDims& d, int64_t n, const __half* src,
                                        int cols) {
  FusedTile t;
  const int warp = threadIdx.x / 32;
  t.lane = threadIdx.x % 32;
  t.ld = fused_ld(d);
  t.w = reinterpret_cast<__half*>(smem);
  __half* acts = t.w + size_t(d.width) * t.ld;
  t.a_in = acts + size_t(warp) * 2 * 16 * t.ld;
  t.a_out = t.a_in + 16 * t.ld;
  const int nw = int(blockDim.x / 32);
  t.f = reinterpret_cast<float*>(acts + size_t(nw) * 2 * 16 * t.ld) + warp * 256;
  t.s0 = (int64_t(blockIdx.x) * nw + warp) * 16;
  t.active = t.s0 < n;
  if (t.active) load_rows(t.a_in, t.ld, src + t.s0 * cols, 16, cols, t.lane, 32);
  return t;
}

// The whole block loads matrix m into shared memory; every thread reaches both barriers.
__device__ inline void fused_load_matrix(const FusedTile& t, const MlpDims& d, const __half* weights, int m) {
  __syncthreads();  // every warp is done with the previous matrix
  load_rows(t.w, t.ld, weights + d.offset[m], d.rows[m], d.cols[m], threadIdx.x, blockDim.x);
  __syncthreads();
}

__device__ inline void fused_next_layer(FusedTile& t) {
  __half* a = t.a_in;
  t.a_in = t.a_out;
  t.a_out = a;
}

template <int W>
__global__ void __launch_bounds__(kMaxWarps * 32)
    fused_forward(MlpDims d, const __half* __restrict__ weights, const __half* __restrict__ X0, int64_t n,
                  __half* __restrict__ acts, float* __restrict__ out, int out_act) {
  extern __shared__ __align__(128) unsigned char smem[];
  FusedTile s = fused_begin(smem, d, n, X0, d.in_pad);
  const int ld = s.ld, lane = s.lane;
  const int64_t s0 = s.s0;
  for (int m = 0; m < d.n_matrices; ++m) {
    const int rows = d.rows[m], cols = d.cols[m];
    const bool last = m == d.n_matrices - 1;
    fused_load_matrix(s, d, weights, m);
    if (!s.active) continue;
    __syncwarp();
    for (int nb = 0; nb < rows / 16; ++nb) {
      wmma::fragment<wmma::accumulator, 16, 16, 16, float> acc;
      wmma::fill_fragment(acc, 0.0f);
      for (int kb = 0; kb < cols / 16; ++kb) {
        wmma::fragment<wmma::matrix_a, 16, 16, 16, __half, wmma::row_major> a;
        wmma::fragment<wmma::matrix_b, 16, 16, 16, __half, wmma::col_major> b;  // W^T: element (k, j) = W[j][k]
        wmma::load_matrix_sync(a, s.a_in + kb * 16, ld);
        wmma::load_matrix_sync(b, s.w + nb * 16 * ld + kb * 16, ld);
        wmma::mma_sync(acc, a, b, acc);
      }
      if (!last)
        for (int t = 0; t < acc.num_elements; ++t) acc.x[t] = acc.x[t] > 0.0f ? acc.x[t] : 0.0f;  // ReLU
      wmma::store_matrix_sync(s.f, acc, 16, wmma::mem_row_major);
      __syncwarp();
      for (int i = lane; i < 256; i += 32) {
        const int r = i / 16, col = nb * 16 + i % 16;
        if (last) {
          if (col < d.n_out) {
            float v = s.f[i];
            out[(s0 + r) * d.n_out + col] = out_act >= 0 ? activate(Activation(out_act), v) : v;
          }
        } else {
          const __half h = __float2half_rn(s.f[i]);
          s.a_out[r * ld + col] = h;
          if (acts) acts[(size_t(m) * n + s0 + r) * W + col] = h;
        }
      }
      __syncwarp();
    }
    fused_next_layer(s);
  }
}

template <int W>
__global__ void __launch_bounds__(kMaxWarps * 32)
    fused_backward(MlpDims d, const __half* __restrict__ weights, const __half* __restrict__ acts,
                   const __half* __restrict__ dOut, int64_t n, __half* __restrict__ dY, __half* __restrict__ dX0) {
  extern __shared__ __align__(128) unsigned char smem[];
  FusedTile s = fused_begin(smem, d, n, dOut, d.out_pad);
  const int ld = s.ld, lane = s.lane;
  const int64_t s0 = s.s0;
  const int first = dX0 ? 0 : 1;
  for (int m = d.n_matrices - 1; m >= first; --m) {
    const int rows = d.rows[m], cols = d.cols[m];
    fused_load_matrix(s, d, weights, m);
    if (!s.active) continue;
    __syncwarp();
    for (int nb = 0; nb < cols / 16; ++nb) {
      wmma::fragment<wmma::accumulator, 16, 16, 16, float> acc;
      wmma::fill_fragment(acc, 0.0f);
      for (int kb = 0; kb < rows / 16; ++kb) {
        wmma::fragment<wmma::matrix_a, 16, 16, 16, __half, wmma::row_major> a;
        wmma::fragment<wmma::matrix_b, 16, 16, 16, __half, wmma::row_major> b;  // W: element (k, j) = W[k][j]
        wmma::load_matrix_sync(a, s.a_in + kb * 16, ld);
        wmma::load_matrix_sync(b, s.w + kb * 16 * ld + nb * 16, ld);
        wmma::mma_sync(acc, a, b, acc);
      }
      wmma::store_matrix_sync(s.f, acc, 16, wmma::mem_row_major);
      __syncwarp();
      for (int i = lane; i < 256; i += 32) {
        const int r = i / 16, col = nb * 16 + i % 16;
        const float v = s.f[i];
        if (m > 0) {  // through the ReLU of hidden layer m-1: its output was > 0
          const size_t at = (size_t(m - 1) * n + s0 + r) * W + col;
          const __half h = __float2half_rn(__half2float(acts[at]) > 0.0f ? v : 0.0f);
          s.a_out[r * ld + col] = h;
          dY[at] = h;
        } else {
          dX0[(s0 + r) * d.in_pad + col] = __float2half_rn(v);
        }
      }
      __syncwarp();
    }
    fused_next_layer(s);
  }
}

// cuBLAS path, elementwise steps between the GEMMs.
__global__ void hidden_from_tmp(const float* __restrict__ tmp, int64_t count, __half* __restrict__ act) {
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i < count) act[i] = __float2half_rn(tmp[i] > 0.0f ? tmp[i] : 0.0f);
}

__global__ void output_from_tmp(const float* __restrict__ tmp, int64_t n, int out_pad, int n_out,
                                float* __restrict__ out, int out_act) {
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n * n_out) return;
  const int64_t s = i / n_out;
  const int o = int(i % n_out);
  const float v = tmp[s * out_pad + o];
  out[i] = out_act >= 0 ? activate(Activation(out_act), v) : v;
}

__global__ void masked_from_tmp(const float* __restrict__ tmp, const __half* __restrict__ act, int64_t count,
                                __half* __restrict__ g) {
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i < count) g[i] = __float2half_rn(act == nullptr || __half2float(act[i]) > 0.0f ? tmp[i] : 0.0f);
}

size_t device_smem_optin() {
  int dev = 0, v = 0;
  VNR_CUDA_CHECK(cudaGetDevice(&dev));
  VNR_CUDA_CHECK(cudaDeviceGetAttribute(&v, cudaDevAttrMaxSharedMemoryPerBlockOptin, dev));
  return size_t(v);
}

template <typename K>
void prepare_kernel(K kernel, size_t smem) {
  if (smem > 48 * 1024)
    VNR_CUDA_CHECK(cudaFuncSetAttribute(kernel, cudaFuncAttributeMaxDynamicSharedMemorySize, int(smem)));
}

// Calls launch(std::integral_constant<int, W>) for the fused kernels' widths.
template <typename Launch>
void with_width(int width, Launch&& launch) {
  switch (width) {
    case 16: launch(std::integral_constant<int, 16>{}); break;
    case 32: launch(std::integral_constant<int, 32>{}); break;
    case 64: launch(std::integral_constant<int, 64>{}); break;
    case 128: launch(std::integral_constant<int, 128>{}); break;
    default: cuda_fail_message("fused MLP: unsupported width " + std::to_string(width));
  }
}

// C (ldc = m) = op(A) * op(B), half inputs, binary32 accumulation and output (column-major, cuBLAS's view).
void gemm(cublasHandle_t blas, cublasOperation_t ta, cublasOperation_t tb, int m, int n, int k, float alpha,
          const __half* A, int lda, const __half* B, int ldb, float* C) {
  const float beta = 0.0f;
  VNR_CUBLAS_CHECK(cublasGemmEx(blas, ta, tb, m, n, k, &alpha, A, CUDA_R_16F, lda, B, CUDA_R_16F, ldb, &beta, C,
                                CUDA_R_32F, m, CUBLAS_COMPUTE_32F, CUBLAS_GEMM_DEFAULT));
}

// The loss-scaled gradient of matrix m's outputs (n rows): dOut for the output layer, else hidden
// layer m's block of dY.
inline const __half* output_grad(const MlpDims& d, const __half* dOut, const __half* dY, int64_t n, int m) {
  return m == d.n_matrices - 1 ? dOut : dY + size_t(m) * n * d.width;
}

}  // namespace

MlpPath resolve_mlp_path(const Network& net, MlpPath asked) {
  const MlpDims d = mlp_dims(net.mlp());
  const bool width_ok = d.width == 16 || d.width == 32 || d.width == 64 || d.width == 128;
  const bool fits = fused_smem_bytes(d) <= device_smem_optin();
  // The fused tiles are 16 wide: CutlassMLP configs pad inputs and outputs to 8 (docs/semantics.md A.4.3).
  const bool pads_ok = d.in_pad % 16 == 0 && d.out_pad == 16;
  if (asked == MlpPath::Fused) {
    if (!pads_ok) cuda_fail_message("the fused MLP needs inputs and outputs padded to 16 (FullyFusedMLP); this "
                                    "model's are padded to 8 (use the cublas path)");
    if (!width_ok) cuda_fail_message("the fused MLP runs widths 16, 32, 64 and 128; this model's width is " +
                                     std::to_string(d.width) + " (use the cublas path)");
    if (!fits) cuda_fail_message("the fused MLP needs " + std::to_string(fused_smem_bytes(d)) +
                                 " bytes of shared memory per block, more than this GPU has (use the cublas path)");
    return MlpPath::Fused;
  }
  if (asked == MlpPath::Cublas) return MlpPath::Cublas;
  return width_ok && fits && pads_ok && net.config().network.fully_fused ? MlpPath::Fused : MlpPath::Cublas;
}

void mlp_forward(MlpPath path, const MlpDims& d, const __half* weights, const __half* X0, int64_t n, __half* acts,
                 float* out, int out_act, float* tmp, cublasHandle_t blas, cudaStream_t st) {
  if (n <= 0) return;
  if (path == MlpPath::Fused) {
    const size_t smem = fused_smem_bytes(d);
    const int nw = fused_warps(d);
    const unsigned blocks = blocks_for(n, 16 * nw);
    with_width(d.width, [&](auto w) {
      constexpr int W = decltype(w)::value;
      prepare_kernel(fused_forward<W>, smem);
      fused_forward<W><<<blocks, nw * 32, smem, st>>>(d, weights, X0, n, acts, out, out_act);
    });
    VNR_CUDA_LAUNCHED();
    return;
  }
  VNR_CUBLAS_CHECK(cublasSetStream(blas, st));
  const __half* in = X0;
  for (int m = 0; m < d.n_matrices; ++m) {
    const int rows = d.rows[m], cols = d.cols[m];
    // tmp (n x rows, sample-major) = in (n x cols) * W_m^T
    gemm(blas, CUBLAS_OP_T, CUBLAS_OP_N, rows, int(n), cols, 1.0f, weights + d.offset[m], cols, in, cols, tmp);
    if (m + 1 < d.n_matrices) {
      __half* a = acts + size_t(m) * n * d.width;
      hidden_from_tmp<<<blocks_for(n * rows, 256), 256, 0, st>>>(tmp, n * rows, a);
      in = a;
    } else {
      output_from_tmp<<<blocks_for(n * d.n_out, 256), 256, 0, st>>>(tmp, n, rows, d.n_out, out, out_act);
    }
    VNR_CUDA_LAUNCHED();
  }
}

void mlp_backward_data(MlpPath path, const MlpDims& d, const __half* weights, const __half* acts, const __half* dOut,
                       int64_t n, __half* dY, __half* dX0, float* tmp, cublasHandle_t blas, cudaStream_t st) {
  if (n <= 0) return;
  if (path == MlpPath::Fused) {
    const size_t smem = fused_smem_bytes(d);
    const int nw = fused_warps(d);
    const unsigned blocks = blocks_for(n, 16 * nw);
    with_width(d.width, [&](auto w) {
      constexpr int W = decltype(w)::value;
      prepare_kernel(fused_backward<W>, smem);
      fused_backward<W><<<blocks, nw * 32, smem, st>>>(d, weights, acts, dOut, n, dY, dX0);
    });
    VNR_CUDA_LAUNCHED();
    return;
  }
  VNR_CUBLAS_CHECK(cublasSetStream(blas, st));
  const int H = d.n_matrices - 1;  // hidden layers
  for (int m = H; m >= (dX0 ? 0 : 1); --m) {
    const int rows = d.rows[m], cols = d.cols[m];
    // tmp (n x cols) = g_m (n x rows) * W_m
    gemm(blas, CUBLAS_OP_N, CUBLAS_OP_N, cols, int(n), rows, 1.0f, weights + d.offset[m], cols,
         output_grad(d, dOut, dY, n, m), rows, tmp);
    const int64_t count = n * cols;
    if (m > 0)
      masked_from_tmp<<<blocks_for(count, 256), 256, 0, st>>>(tmp, acts + size_t(m - 1) * n * d.width, count,
                                                               dY + size_t(m - 1) * n * d.width);
    else
      masked_from_tmp<<<blocks_for(count, 256), 256, 0, st>>>(tmp, nullptr, count, dX0);
    VNR_CUDA_LAUNCHED();
  }
}

void mlp_weight_gradients(const MlpDims& d, const __half* X0, const __half* acts, const __half* dOut,
                          const __half* dY, int64_t n, float* dW, cublasHandle_t blas, cudaStream_t st) {
  if (n <= 0) return;
  VNR_CUBLAS_CHECK(cublasSetStream(blas, st));
  // dW_m (rows x cols) = g_m^T (rows x n) * In_m (n x cols) / S.
  for (int m = 0; m < d.n_matrices; ++m) {
    const int rows = d.rows[m], cols = d.cols[m];
    const __half* in = m == 0 ? X0 : acts + size_t(m - 1) * n * d.width;
    gemm(blas, CUBLAS_OP_N, CUBLAS_OP_T, cols, rows, int(n), 1.0f / kLossScale, in, cols,
         output_grad(d, dOut, dY, n, m), rows, dW + d.offset[m]);
  }
}

}  // namespace vnr::cuda
