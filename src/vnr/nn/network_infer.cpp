// Batched inference: chunks of kChunk points encoded and run through the fp32 or bf16 MLP, claimed by
// the threads of parallel_threads (Network::infer_fn in network.h).
#include <algorithm>
#include <vector>
#include "vnr/nn/cpu_kernels.h"
#include "vnr/nn/loss.h"
#include "vnr/nn/mlp_bf16.h"
#include "vnr/nn/mlp_kernels.h"
#include "vnr/nn/network.h"

namespace vnr {

float* Network::thread_workspace(size_t floats) {
  thread_local std::vector<float> ws;
  if (ws.size() < floats) ws.resize(floats);
  return ws.data();
}

bool Network::fused_16(int n) const {
  const MlpLayout& m = mlp_;
  return m.activation == Activation::ReLU && m.width == 16 && m.n_out == 1 && m.n_hidden <= 16 && n % 16 == 0;
}

size_t Network::infer_workspace_floats() const {
  // fp32: X0, every hidden activation, the output's pre-activation and activation.
  // bf16: X0, its pairs, two pair buffers for the hidden layers, the output.
  const size_t fp32 = size_t(mlp_.in_pad) + size_t(mlp_.n_hidden) * mlp_.width + 2 * size_t(mlp_.n_out);
  return std::max(fp32 * kChunk, size_t(mlp_.in_pad) * kChunk + mlp_bf16_scratch(kChunk));
}

void Network::set_inference_precision(Precision p) {
  const bool applies = mlp_.activation == Activation::ReLU && mlp_.width % 2 == 0 && kernels::bf16_supported();
  precision_ = p == Precision::BF16 && applies ? Precision::BF16 : Precision::FP32;
}

void Network::infer_chunk_bf16(const float* x, const float* y, const float* z, int n, float* out, float* ws,
                               const uint32_t* wp) const {
  float* X0 = ws;
  encode(x, y, z, n, X0);
  mlp_forward_bf16(X0, n, wp, reinterpret_cast<uint32_t*>(X0 + size_t(mlp_.in_pad) * n), out);
}

void Network::infer_chunk(const float* x, const float* y, const float* z, int n, float* out, float* ws) const {
  const MlpLayout& m = mlp_;
  float* X0 = ws;
  float* acts = X0 + size_t(m.in_pad) * n;
  float* pre = acts + acts_floats(n);
  float* y_out = pre + size_t(m.n_out) * n;
  encode(x, y, z, n, X0);
  if (fused_16(n)) {
    // 16-wide networks: the whole forward pass in registers (the tiled GEMMs cannot fill the FMA pipes).
    const float* Wh[16];
    for (uint32_t k = 1; k < m.n_hidden; ++k) Wh[k - 1] = params_.data() + m.offset[k];
    kernels::mlp_forward_16(params_.data() + m.offset[0], int(m.first_cols), int(m.in_pad), Wh, int(m.n_hidden - 1),
                            params_.data() + m.offset[m.n_hidden], X0, n, pre);
    activate_n(m.output_activation, pre, n, out);
    return;
  }
  mlp_forward(X0, n, acts, pre, y_out);
  std::copy(y_out, y_out + n, out);  // the first output row
}

void Network::infer(const float* coords, int64_t n, float* out) const {
  infer_fn(
      n,
      [&](int64_t first, int64_t count, float* x, float* y, float* z) {
        kernels::deinterleave_xyz(coords + 3 * first, count, x, y, z);
      },
      out);
}

}  // namespace vnr
