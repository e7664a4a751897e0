#pragma once
// bf16 inference kernels for the MLP forward pass (AVX512-BF16 `vdpbf16ps`): weights and activations
// rounded to bf16 (round to nearest even), products summed in fp32. One vdpbf16ps does two
// multiply-adds per fp32 lane at the rate of one fp32 FMA, so where the CPU runs it at full rate the
// MLP can reach twice the fp32 FMA peak (docs/benchmarks.md "MLP kernels (CPU)"). Inference;
// training has its own sample-major kernels (mlp_bf16_train.h).
//
// Layout "pairs": an activation matrix X (K x n, feature-major) is stored as P[j * n + s] (uint32)
// = bf16(X[2j][s]) in the low half, bf16(X[2j + 1][s]) in the high half (0 past K), which is the
// operand order of vdpbf16ps with one sample per fp32 lane. Weights W (rows x K, row-major) become
// Wp[i * kp + j] = bf16 pair (W[i][2j], W[i][2j + 1]), kp = ceil(K / 2).
#include <cstdint>

namespace vnr::kernels {

// True when this CPU has AVX512-BF16 (checked once); the callers fall back to fp32 otherwise.
bool bf16_supported();
// What `--precision auto` takes: bf16 where it is supported and pays. AMD's AVX512-BF16 cores
// run vdpbf16ps at the fp32 FMA rate, twice the multiply-adds; on Intel Xeons with AVX512-BF16 the
// bf16 kernels did not beat fp32 (docs/benchmarks.md "CUDA backend"), so auto keeps fp32 on Intel.
bool bf16_preferred();

uint16_t to_bf16(float f);  // round to nearest even; NaN stays NaN
float from_bf16(uint16_t h);
uint32_t bf16_pair(float lo, float hi);  // to_bf16(lo) | to_bf16(hi) << 16

// Wp (rows x kp pairs) from W's first K columns (row stride ldw).
void weights_to_bf16_pairs(const float* W, int rows, int K, int ldw, uint32_t* Wp);
// P (ceil(K/2) x n pairs) from X (K x n floats); n a multiple of 16.
void activations_to_bf16_pairs(const float* X, int K, int n, uint32_t* P);

// Hidden layer: Yp (rows/2 x n pairs) = pairs(ReLU(W X)); rows even, n a multiple of 16.
void matmul_fwd_bf16_relu(const uint32_t* Wp, int rows, int kp, const uint32_t* Xp, uint32_t* Yp, int n);
// Output layer: Y (rows x n floats) = W X, no activation.
void matmul_fwd_bf16_linear(const uint32_t* Wp, int rows, int kp, const uint32_t* Xp, float* Y, int n);

// Whole forward pass of a 16-wide ReLU MLP with one output (the bf16 twin of mlp_forward_16): W0 is
// 16 x ceil(k0 / 2) pairs, Wh[0..n_mid) 16 x 8 pairs, Wout 8 pairs (output row 0); X0 (k0 x n
// floats) rounded to bf16 on the fly; out = the output's pre-activation; n a multiple of 16.
void mlp_forward_16_bf16(const uint32_t* W0, int k0, const uint32_t* const* Wh, int n_mid, const uint32_t* Wout,
                         const float* X0, int n, float* out);

namespace ref {
// Scalar references: the same bf16 operands, products summed in double.
void matmul_fwd_bf16_relu(const uint32_t* Wp, int rows, int kp, const uint32_t* Xp, uint32_t* Yp, int n);
void matmul_fwd_bf16_linear(const uint32_t* Wp, int rows, int kp, const uint32_t* Xp, float* Y, int n);
}  // namespace ref

}  // namespace vnr::kernels
