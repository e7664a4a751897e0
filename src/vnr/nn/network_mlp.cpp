// The fp32 MLP of one chunk: forward through tiled GEMMs and the backward pass of training.
#include <utility>
#include "vnr/nn/loss.h"
#include "vnr/nn/mlp_kernels.h"
#include "vnr/nn/network.h"

namespace vnr {

void Network::mlp_forward(const float* X0, int n, float* acts, float* out_pre, float* out) const {
  const MlpLayout& m = mlp_;
  const bool relu = m.activation == Activation::ReLU;
  const float* in = X0;
  for (uint32_t k = 0; k < m.n_hidden; ++k) {
    float* h = acts + size_t(k) * m.width * n;
    const int cols = k == 0 ? int(m.first_cols) : int(m.cols[k]);
    kernels::matmul_fwd(params_.data() + m.offset[k], int(m.rows[k]), cols, in, h, n, relu, int(m.cols[k]));
    in = h;
  }
  // Output layer: only the n_out real rows are computed; tcnn's padded rows never reach the loss.
  kernels::matmul_fwd(params_.data() + m.offset[m.n_hidden], int(m.n_out), int(m.width), in, out_pre, n, false);
  activate_n(m.output_activation, out_pre, int64_t(m.n_out) * n, out);
}

void Network::mlp_backward(const float* X0, const float* acts, const float* d_out_pre, int n, float* dW, float* dX0,
                           float* scratch) const {
  const MlpLayout& m = mlp_;
  const bool relu = m.activation == Activation::ReLU;
  const size_t wn = size_t(m.width) * n;
  float* g_cur = scratch;        // dL/d(pre-activation) of the current hidden layer
  float* g_next = scratch + wn;
  const uint32_t H = m.n_hidden;
  const float* hH = acts + size_t(H - 1) * wn;
  kernels::matmul_bwd_weights(d_out_pre, int(m.n_out), hH, int(m.width), n, dW + m.offset[H]);
  kernels::matmul_bwd_data(params_.data() + m.offset[H], int(m.n_out), int(m.width), d_out_pre, relu ? hH : nullptr,
                           g_cur, n);
  for (uint32_t k = H - 1; k >= 1; --k) {
    const float* hk = acts + size_t(k - 1) * wn;  // input of matrix k
    kernels::matmul_bwd_weights(g_cur, int(m.width), hk, int(m.width), n, dW + m.offset[k]);
    kernels::matmul_bwd_data(params_.data() + m.offset[k], int(m.width), int(m.width), g_cur, relu ? hk : nullptr,
                             g_next, n);
    std::swap(g_cur, g_next);
  }
  // Gradients of the zero-padded input columns are exactly 0 and not computed; dX0 rows past the
  // encoding width are not written (nothing reads them).
  const int k0 = int(m.first_cols);
  kernels::matmul_bwd_weights(g_cur, int(m.width), X0, k0, n, dW + m.offset[0], int(m.in_pad));
  if (dX0)
    kernels::matmul_bwd_data(params_.data() + m.offset[0], int(m.width), k0, g_cur, nullptr, dX0, n, int(m.in_pad));
}

}  // namespace vnr
