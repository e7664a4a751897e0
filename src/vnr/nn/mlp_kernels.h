#pragma once
// Hot MLP kernels (CPU). Layout: activations are feature-major per chunk of n samples:
// X[c * n + s] is feature c of sample s (n a multiple of 16). Weights are row-major with
// rows = outputs (tcnn layout): W[r * cols + c].
// The dispatching versions pick the best SIMD target at run time (Highway); kernels::ref holds
// the portable scalar reference they are tested against.
#include "vnr/device.h"  // simd_target_name

namespace vnr::kernels {

// ldw is W's row stride (0 = cols): a layer can use only the first `cols` columns of a wider matrix
// (the zero-padded encoding inputs of tcnn's layout contribute nothing and are skipped).
// Y[r*n + s] = act(sum_c W[r*ldw + c] * X[c*n + s]); act = ReLU when relu, else identity.
void matmul_fwd(const float* W, int rows, int cols, const float* X, float* Y, int n, bool relu, int ldw = 0);
// dX[c*n + s] = (sum_r W[r*ldw + c] * dY[r*n + s]) * (mask == nullptr || mask[c*n + s] > 0 ? 1 : 0)
void matmul_bwd_data(const float* W, int rows, int cols, const float* dY, const float* mask, float* dX, int n,
                     int ldw = 0);
// dW[r*ldw + c] += sum_s dY[r*n + s] * X[c*n + s]
void matmul_bwd_weights(const float* dY, int rows, const float* X, int cols, int n, float* dW, int ldw = 0);
// Whole forward pass of a 16-wide, bias-free ReLU MLP with one output (pre-activation) for n samples
// (n a multiple of 16), activations kept in registers: W0 is 16 x ldw0 of which the first k0 columns
// are used; Wh[0..n_mid) are the 16 x 16 hidden matrices; Wout the 16 weights of output row 0.
void mlp_forward_16(const float* W0, int k0, int ldw0, const float* const* Wh, int n_mid, const float* Wout,
                    const float* X0, int n, float* out);
// simd_target_name(): vnr/device.h (public).

namespace ref {
void matmul_fwd(const float* W, int rows, int cols, const float* X, float* Y, int n, bool relu, int ldw = 0);
void matmul_bwd_data(const float* W, int rows, int cols, const float* dY, const float* mask, float* dX, int n,
                     int ldw = 0);
void matmul_bwd_weights(const float* dY, int rows, const float* X, int cols, int n, float* dW, int ldw = 0);
}  // namespace ref

}  // namespace vnr::kernels
