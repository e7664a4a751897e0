#pragma once
// The GPU MLP (CUDA-only header). Layout, all sample-major: the encoding X0 is n x in_pad half, hidden
// activations (post-ReLU) n_hidden blocks of n x width half, the output n x n_out binary32
// (pre-activation). Weights are the half working copy in tcnn order: matrix m is rows_m x cols_m,
// row-major (rows = outputs), at offset_m.
#include <cublas_v2.h>
#include <cuda_fp16.h>
#include <cuda_runtime.h>
#include "vnr/cuda/common.h"
#include "vnr/cuda/cuda.h"
#include "vnr/nn/network.h"

namespace vnr::cuda {

constexpr float kLossScale = 128.0f;  // docs/semantics.md A.6: half gradients are scaled by S = 128

struct MlpDims {
  int in_pad = 0, width = 0, n_matrices = 0, n_out = 1, out_pad = 16;
  int rows[34], cols[34];
  uint32_t offset[34];
};
MlpDims mlp_dims(const MlpLayout& m);

// Chooses the path for this network on the current device (Auto: fused when the width is 16/32/64/128,
// the config asks for FullyFusedMLP and the kernel's shared memory fits; cuBLAS otherwise).
MlpPath resolve_mlp_path(const Network& net, MlpPath asked);

// Forward for n samples (n a multiple of 16). out_act >= 0 applies that
// Activation to the outputs (inference); -1 leaves them pre-activation (training, the loss applies it).
// acts may be null only on the fused path. tmp: n * max(in_pad, width) floats, used by the cuBLAS path only.
void mlp_forward(MlpPath path, const MlpDims& d, const __half* weights, const __half* X0, int64_t n, __half* acts,
                 float* out, int out_act, float* tmp, cublasHandle_t blas, cudaStream_t s);

// Backward through the layers for n samples. dOut: n x out_pad half, the loss-scaled gradient of the
// output pre-activation. dY: n_hidden blocks of n x width half (gradients of the hidden pre-activations,
// written here). dX0: n x in_pad half, dL/dX0 (loss-scaled), or null. tmp as in mlp_forward.
void mlp_backward_data(MlpPath path, const MlpDims& d, const __half* weights, const __half* acts, const __half* dOut,
                       int64_t n, __half* dY, __half* dX0, float* tmp, cublasHandle_t blas, cudaStream_t s);

// The weight gradients of that pass, on either path: dW, the binary32 gradient of the MLP parameters
// (tcnn order), overwritten and already divided by the loss scale; one cuBLAS GEMM per matrix.
void mlp_weight_gradients(const MlpDims& d, const __half* X0, const __half* acts, const __half* dOut,
                          const __half* dY, int64_t n, float* dW, cublasHandle_t blas, cudaStream_t s);

}  // namespace vnr::cuda
