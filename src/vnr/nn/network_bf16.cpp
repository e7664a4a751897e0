// The bf16 paths of the MLP (kernels in mlp_bf16.h, mlp_bf16_train.h): the inference forward and the
// forward/backward of bf16 training, with their weight layouts and scratch.
#include <algorithm>
#include <utility>
#include "vnr/error.h"
#include "vnr/nn/loss.h"
#include "vnr/nn/mlp_bf16.h"
#include "vnr/nn/mlp_bf16_train.h"
#include "vnr/nn/network.h"

namespace vnr {

std::vector<uint32_t> Network::bf16_weights() const {
  const MlpLayout& m = mlp_;
  const int kpw = int(m.width) / 2, kp0 = int(m.first_cols + 1) / 2;
  std::vector<uint32_t> wp(size_t(m.width) * kp0 + size_t(m.n_hidden - 1) * m.width * kpw + size_t(m.n_out) * kpw);
  uint32_t* w = wp.data();
  for (uint32_t k = 0; k <= m.n_hidden; ++k) {
    const int rows = k == m.n_hidden ? int(m.n_out) : int(m.width);
    const int K = k == 0 ? int(m.first_cols) : int(m.width);
    kernels::weights_to_bf16_pairs(params_.data() + m.offset[k], rows, K, int(m.cols[k]), w);
    w += size_t(rows) * ((K + 1) / 2);
  }
  return wp;
}

namespace {

// Lanes of a pair-GEMM operand of K values: 16 V with V in {1, 2, 4, 8} (0 when K > 128).
int bf16_lanes(uint32_t K) {
  for (int v = 1; v <= 8; v *= 2)
    if (K <= uint32_t(16 * v)) return 16 * v;
  return 0;
}

// Where each buffer of one chunk's bf16 training lives in the scratch words (n samples).
struct Bf16TrainScratch {
  uint64_t A0, A, g0, g1, GS, XS, DP, DS, dX0, total;
  int kp0, lanes0, W;
  Bf16TrainScratch(const MlpLayout& m, int n) {
    W = int(m.width);
    kp0 = int(m.first_cols + 1) / 2;
    lanes0 = bf16_lanes(m.first_cols);
    const uint64_t nn = uint64_t(n), half_w = uint64_t(W) / 2;
    uint64_t o = 0;
    auto take = [&](uint64_t words) { const uint64_t at = o; o += (words + 15) / 16 * 16; return at; };
    A0 = take(nn * kp0);
    A = take(m.n_hidden * nn * half_w);  // layer k's output at A + k * n * W / 2
    g0 = take(nn * half_w);
    g1 = take(nn * half_w);
    GS = take(nn / 2 * std::max<uint64_t>(W, m.n_out));
    XS = take(nn / 2 * std::max<uint64_t>(W, lanes0));
    DP = take(nn * ((m.n_out + 1) / 2));
    DS = take(nn / 2 * m.n_out);
    dX0 = take(nn * lanes0);
    total = o;
  }
};

}  // namespace

bool Network::bf16_training_supported() const {
  const MlpLayout& m = mlp_;
  const bool width_ok = m.width == 16 || m.width == 32 || m.width == 64 || m.width == 128;
  return kernels::bf16_supported() && m.activation == Activation::ReLU && width_ok && m.n_hidden >= 1 &&
         bf16_lanes(m.first_cols) > 0 && bf16_lanes(m.n_out) > 0;
}

Network::Bf16TrainWeights Network::bf16_train_weights() const {
  const MlpLayout& m = mlp_;
  Bf16TrainWeights w;
  uint64_t size = 0;
  for (uint32_t k = 0; k <= m.n_hidden; ++k) {
    const uint32_t R = k == m.n_hidden ? m.n_out : m.width, K = k == 0 ? m.first_cols : m.width;
    w.wt[k] = size;
    size += uint64_t((K + 1) / 2) * bf16_lanes(R);
    w.wp[k] = size;
    size += uint64_t((R + 1) / 2) * bf16_lanes(K);
  }
  w.data.assign(size, 0u);
  for (uint32_t k = 0; k <= m.n_hidden; ++k) {
    const int R = int(k == m.n_hidden ? m.n_out : m.width), K = int(k == 0 ? m.first_cols : m.width);
    const int LR = bf16_lanes(uint32_t(R)), LK = bf16_lanes(uint32_t(K));
    const float* Wk = params_.data() + m.offset[k];
    const size_t ld = m.cols[k];
    auto at = [&](int r, int c) { return r < R && c < K ? Wk[size_t(r) * ld + c] : 0.0f; };
    uint32_t* wt = w.data.data() + w.wt[k];
    for (int c2 = 0; c2 < (K + 1) / 2; ++c2)
      for (int r = 0; r < LR; ++r) wt[size_t(c2) * LR + r] = kernels::bf16_pair(at(r, 2 * c2), at(r, 2 * c2 + 1));
    uint32_t* wp = w.data.data() + w.wp[k];
    for (int r2 = 0; r2 < (R + 1) / 2; ++r2)
      for (int c = 0; c < LK; ++c) wp[size_t(r2) * LK + c] = kernels::bf16_pair(at(2 * r2, c), at(2 * r2 + 1, c));
  }
  return w;
}

size_t Network::mlp_train_bf16_scratch(int n) const { return Bf16TrainScratch(mlp_, n).total; }

void Network::mlp_forward_train_bf16(const float* X0, int n, const Bf16TrainWeights& w, uint32_t* scratch,
                                     float* out_pre, float* out) const {
  const MlpLayout& m = mlp_;
  if (n % 32) fail("bf16 training works on multiples of 32 samples, got {}", n);
  const Bf16TrainScratch L(m, n);
  const int W = L.W;
  kernels::feature_major_to_sm_pairs(X0, int(m.first_cols), n, scratch + L.A0, L.kp0);
  const uint32_t* in = scratch + L.A0;
  int kin = L.kp0;
  for (uint32_t k = 0; k < m.n_hidden; ++k) {
    uint32_t* h = scratch + L.A + uint64_t(k) * n * (W / 2);
    kernels::PairGemm g;
    g.P = in, g.si = kin, g.sk = 1, g.kp = kin;
    g.Q = w.data.data() + w.wt[k], g.ldq = W, g.V = W / 16, g.M = n;
    g.out = kernels::PairGemmOut::ReluBf16, g.dst = h, g.ld = W;
    kernels::pair_gemm(g);
    in = h;
    kin = W / 2;
  }
  const int lanes_out = bf16_lanes(m.n_out);
  kernels::PairGemm g;
  g.P = in, g.si = kin, g.sk = 1, g.kp = kin;
  g.Q = w.data.data() + w.wt[m.n_hidden], g.ldq = lanes_out, g.V = lanes_out / 16, g.M = n;
  g.out = kernels::PairGemmOut::Column, g.dst = out_pre, g.ld = n, g.valid = int(m.n_out);
  kernels::pair_gemm(g);
  activate_n(m.output_activation, out_pre, int64_t(m.n_out) * n, out);
}

void Network::mlp_backward_train_bf16(const float* d_out_pre, int n, const Bf16TrainWeights& w, uint32_t* scratch,
                                      float* dW, float* dX0) const {
  const MlpLayout& m = mlp_;
  if (n % 32) fail("bf16 training works on multiples of 32 samples, got {}", n);
  const Bf16TrainScratch L(m, n);
  const int W = L.W, no = int(m.n_out), nop = (no + 1) / 2, H = int(m.n_hidden);
  auto acts = [&](int k) {  // input of matrix k, bf16 words
    return reinterpret_cast<const uint16_t*>(k == 0 ? scratch + L.A0 : scratch + L.A + uint64_t(k - 1) * n * (W / 2));
  };
  uint32_t *DP = scratch + L.DP, *DS = scratch + L.DS, *GS = scratch + L.GS, *XS = scratch + L.XS;
  uint32_t *g = scratch + L.g0, *g_next = scratch + L.g1;
  // The output gradient in both pair layouts: over outputs (data gradient) and over samples (dW).
  for (int s = 0; s < n; ++s)
    for (int o2 = 0; o2 < nop; ++o2)
      DP[size_t(s) * nop + o2] = kernels::bf16_pair(d_out_pre[size_t(2 * o2) * n + s],
                                                    2 * o2 + 1 < no ? d_out_pre[size_t(2 * o2 + 1) * n + s] : 0.0f);
  for (int j = 0; j < n / 2; ++j)
    for (int o = 0; o < no; ++o)
      DS[size_t(j) * no + o] = kernels::bf16_pair(d_out_pre[size_t(o) * n + 2 * j], d_out_pre[size_t(o) * n + 2 * j + 1]);
  // Output matrix: dW_H += dout h_H^T; g = (W_H^T dout) * relu'(h_H).
  kernels::sample_pairs(acts(H), W, W, n, XS, W);
  kernels::PairGemm gw;
  gw.P = DS, gw.si = 1, gw.sk = no, gw.kp = n / 2;
  gw.Q = XS, gw.ldq = W, gw.V = W / 16, gw.M = no;
  gw.out = kernels::PairGemmOut::AddF32, gw.dst = dW + m.offset[H], gw.ld = int64_t(m.cols[H]), gw.valid = W;
  kernels::pair_gemm(gw);
  kernels::PairGemm gd;
  gd.P = DP, gd.si = nop, gd.sk = 1, gd.kp = nop;
  gd.Q = w.data.data() + w.wp[H], gd.ldq = W, gd.V = W / 16, gd.M = n;
  gd.out = kernels::PairGemmOut::MaskBf16, gd.dst = g, gd.ld = W, gd.mask = acts(H), gd.mask_ld = W;
  kernels::pair_gemm(gd);
  for (int k = H - 1; k >= 0; --k) {
    const int K = k > 0 ? W : int(m.first_cols), LK = k > 0 ? W : L.lanes0, lda = k > 0 ? W : 2 * L.kp0;
    kernels::sample_pairs(reinterpret_cast<const uint16_t*>(g), W, W, n, GS, W);
    kernels::sample_pairs(acts(k), lda, K, n, XS, LK);
    gw.P = GS, gw.si = 1, gw.sk = W, gw.kp = n / 2;
    gw.Q = XS, gw.ldq = LK, gw.V = LK / 16, gw.M = W;
    gw.dst = dW + m.offset[k], gw.ld = int64_t(m.cols[k]), gw.valid = K;
    kernels::pair_gemm(gw);
    if (k == 0 && !dX0) break;
    gd.P = g, gd.si = W / 2, gd.sk = 1, gd.kp = W / 2;
    gd.Q = w.data.data() + w.wp[k], gd.ldq = LK, gd.V = LK / 16, gd.M = n;
    if (k > 0) {
      gd.out = kernels::PairGemmOut::MaskBf16, gd.dst = g_next, gd.ld = W, gd.mask = acts(k), gd.mask_ld = W;
      kernels::pair_gemm(gd);
      std::swap(g, g_next);
    } else {
      float* dX0s = reinterpret_cast<float*>(scratch + L.dX0);
      gd.out = kernels::PairGemmOut::F32, gd.dst = dX0s, gd.ld = LK;
      kernels::pair_gemm(gd);
      kernels::sm_to_feature_major(dX0s, LK, K, n, dX0, n);
    }
  }
}

void Network::mlp_forward_bf16(const float* X0, int n, const uint32_t* wp, uint32_t* scratch, float* out) const {
  const MlpLayout& m = mlp_;
  const int kp0 = int(m.first_cols + 1) / 2, kpw = int(m.width) / 2;
  float* pre = reinterpret_cast<float*>(scratch);
  if (fused_16(n)) {  // as the fp32 path: the whole forward pass in registers
    const uint32_t* Wh[16];
    for (uint32_t k = 1; k < m.n_hidden; ++k) Wh[k - 1] = wp + size_t(16) * kp0 + size_t(k - 1) * 16 * kpw;
    kernels::mlp_forward_16_bf16(wp, int(m.first_cols), Wh, int(m.n_hidden - 1),
                                 wp + size_t(16) * kp0 + size_t(m.n_hidden - 1) * 16 * kpw, X0, n, pre);
    activate_n(m.output_activation, pre, n, out);
    return;
  }
  uint32_t* P0 = scratch;
  uint32_t* pairs[2] = {P0 + size_t(kp0) * n, P0 + size_t(kp0 + kpw) * n};
  pre = reinterpret_cast<float*>(pairs[1] + size_t(kpw) * n);
  kernels::activations_to_bf16_pairs(X0, int(m.first_cols), n, P0);
  const uint32_t* in = P0;
  int kp = kp0;
  for (uint32_t k = 0; k < m.n_hidden; ++k) {
    kernels::matmul_fwd_bf16_relu(wp, int(m.width), kp, in, pairs[k & 1], n);
    wp += size_t(m.width) * kp;
    in = pairs[k & 1];
    kp = kpw;
  }
  kernels::matmul_fwd_bf16_linear(wp, int(m.n_out), kpw, in, pre, n);  // row 0 is the first output
  activate_n(m.output_activation, pre, n, out);
}

}  // namespace vnr
