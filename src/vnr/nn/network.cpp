#include "vnr/nn/network.h"
#include <algorithm>
#include <cmath>
#include <cstring>
#include <numeric>
#include "vnr/core/error.h"
#include "vnr/core/half.h"
#include "vnr/core/math.h"
#include "vnr/core/rng.h"
#include "vnr/nn/cpu_kernels.h"
#include "vnr/nn/loss.h"
#include "vnr/nn/mlp_bf16.h"
#include "vnr/nn/mlp_bf16_train.h"
#include "vnr/nn/mlp_kernels.h"

namespace vnr {
namespace {

constexpr float kPi = 3.14159265358979323846f;

uint32_t encoding_width(const EncodingConfig& e) {
  switch (e.type) {
    case EncodingType::Grid: return e.n_levels * e.n_features_per_level;
    case EncodingType::Frequency: return 3 * 2 * e.n_frequencies;
    case EncodingType::OneBlob: return 3 * e.n_bins;
    case EncodingType::Identity: return 3;
  }
  return 0;
}

uint32_t encoding_min_alignment(const EncodingConfig& e) {
  switch (e.type) {
    case EncodingType::Grid: return e.n_features_per_level;
    case EncodingType::OneBlob: return e.n_bins;
    default: return 1;
  }
}

// OneBlob's quartic kernel CDF (compat.md A.3.3) and its derivative in t.
float oneblob_q(float t, float n) {
  float u = t * n;
  float v = (15.0f / 16.0f) * u * (1.0f - (2.0f / 3.0f) * u * u + (1.0f / 5.0f) * u * u * u * u) + 0.5f;
  return clampf(v, 0.0f, 1.0f);
}
float oneblob_dq(float t, float n) {
  float u = t * n;
  if (u <= -1.0f || u >= 1.0f) return 0.0f;
  float a = 1.0f - u * u;
  return (15.0f / 16.0f) * n * a * a;
}

}  // namespace

MlpLayout make_mlp_layout(const ModelConfig& cfg, uint32_t n_output_dims) {
  MlpLayout m;
  const NetworkConfig& nc = cfg.network;
  const uint32_t align = nc.fully_fused ? 16u : 8u;
  m.enc_width = encoding_width(cfg.encoding);
  m.in_pad = uint32_t(next_multiple(m.enc_width, std::lcm(align, encoding_min_alignment(cfg.encoding))));
  m.pad_value = cfg.encoding.type == EncodingType::Grid ? 0.0f : 1.0f;
  m.first_cols = m.pad_value == 0.0f ? m.enc_width : m.in_pad;
  m.width = nc.n_neurons;
  m.n_hidden = nc.n_hidden_layers;
  m.n_out = n_output_dims;
  m.out_pad = uint32_t(next_multiple(n_output_dims, align));
  m.activation = nc.activation;
  m.output_activation = nc.output_activation;
  m.n_matrices = m.n_hidden + 1;
  uint64_t off = 0;
  for (uint32_t k = 0; k < m.n_matrices; ++k) {
    m.rows[k] = k == m.n_hidden ? m.out_pad : m.width;
    m.cols[k] = k == 0 ? m.in_pad : m.width;
    m.offset[k] = off;
    off += m.rows[k] * m.cols[k];
  }
  m.n_params = off;
  return m;
}

uint64_t count_params(const ModelConfig& c, uint32_t n_output_dims) {
  uint64_t grid = c.encoding.type == EncodingType::Grid ? make_grid_layout(c.encoding).n_params() : 0;
  return make_mlp_layout(c, n_output_dims).n_params + grid;
}

Network::Network(const ModelConfig& config, uint32_t n_output_dims)
    : cfg_(config), cfg_json_(cfg_.to_json()) {  // canonical: every key explicit
  if (has_grid()) grid_ = make_grid_layout(cfg_.encoding);
  mlp_ = make_mlp_layout(cfg_, n_output_dims);
  params.assign(n_params(), 0.0f);
  grid_half_.assign(grid_params(), 0);
}

void Network::sync_half_table() { floats_to_halves(grid_table(), grid_half_.data(), grid_params()); }

double Network::flops_forward_per_sample() const {
  // The work actually done: the first layer skips zero-padded inputs (first_cols).
  double mac = double(mlp_.width) * mlp_.first_cols + double(mlp_.n_hidden - 1) * mlp_.width * mlp_.width +
               double(mlp_.n_out) * mlp_.width;
  return 2.0 * mac;
}

void Network::init_params(uint32_t seed) {
  Pcg32 rng(seed_seq_first_word(seed));
  for (uint32_t k = 0; k < mlp_.n_matrices; ++k) {
    float fan_in = float(mlp_.cols[k]), fan_out = float(mlp_.rows[k]);
    float b = std::sqrt(6.0f / (fan_in + fan_out));
    float* w = params.data() + mlp_.offset[k];
    for (uint64_t i = 0; i < mlp_.rows[k] * mlp_.cols[k]; ++i) w[i] = rng.next_float() * 2.0f * b - b;
  }
  if (!has_grid()) return;
  tcnn_uniform_fill(rng, grid_table(), grid_params(), -1e-4f, 1e-4f);
  sync_half_table();
}

void tcnn_uniform_fill(Pcg32& rng, float* out, uint64_t n, float lower, float upper) {
  // One sequential pass over stream positions q = 0..4T-1 fills element (q / 4) + T * (q % 4).
  const uint64_t T = (((n + 3) / 4 + 127) / 128) * 128;
  const Pcg32 entry = rng;
  const float span = upper - lower;
  for (uint64_t q = 0; q < 4 * T; ++q) {
    float u = rng.next_float();
    uint64_t idx = (q >> 2) + T * (q & 3);
    if (idx < n) out[idx] = std::fma(u, span, lower);
  }
  rng = entry;
  rng.advance(n);
}

std::vector<uint16_t> Network::params_half() const {
  std::vector<uint16_t> h(params.size());
  floats_to_halves(params.data(), h.data(), h.size());
  return h;
}

void Network::set_params_half(const std::vector<uint16_t>& h) {
  if (h.size() != params.size())
    fail("model has {} parameters but its configuration needs {}", h.size(), params.size());
  halves_to_floats(h.data(), params.data(), h.size());
  std::copy(h.begin() + int64_t(mlp_.n_params), h.end(), grid_half_.begin());
}

void Network::encode(const float* x, const float* y, const float* z, int n, float* X0) const {
  const MlpLayout& m = mlp_;
  const EncodingConfig& e = cfg_.encoding;
  switch (e.type) {
    case EncodingType::Grid: {
      kernels::grid_encode(grid_, grid_half(), x, y, z, n, X0);
      break;
    }
    default: {
      static_assert(kMaxParameterFreeWidth >= 3 * 2 * kMaxFrequencies);
      float buf[kMaxParameterFreeWidth];
      for (int s = 0; s < n; ++s) {
        const float p[3] = {x[s], y[s], z[s]};
        encode_point(p, buf);
        for (uint32_t j = 0; j < m.enc_width; ++j) X0[size_t(j) * n + s] = buf[j];
      }
    }
  }
  for (uint32_t j = m.enc_width; j < m.in_pad; ++j)
    for (int s = 0; s < n; ++s) X0[size_t(j) * n + s] = m.pad_value;
}

void Network::encode_point(const float xyz[3], float* out) const {
  const EncodingConfig& e = cfg_.encoding;
  switch (e.type) {
    case EncodingType::Grid:
      for (uint32_t l = 0; l < grid_.n_levels; ++l) {
        const GridLevel& L = grid_.levels[l];
        float* o = out + l * grid_.n_features;
        switch (grid_.n_features) {
          case 1: grid_level_forward<1>(L, grid_.interpolation, grid_half(), xyz[0], xyz[1], xyz[2], o, 1); break;
          case 2: grid_level_forward<2>(L, grid_.interpolation, grid_half(), xyz[0], xyz[1], xyz[2], o, 1); break;
          case 4: grid_level_forward<4>(L, grid_.interpolation, grid_half(), xyz[0], xyz[1], xyz[2], o, 1); break;
          case 8: grid_level_forward<8>(L, grid_.interpolation, grid_half(), xyz[0], xyz[1], xyz[2], o, 1); break;
        }
      }
      break;
    case EncodingType::Frequency: {
      const uint32_t nf = e.n_frequencies;
      for (uint32_t j = 0; j < 3 * 2 * nf; ++j) {
        uint32_t d = j / (2 * nf), k = (j / 2) % nf;
        float arg = std::ldexp(1.0f, int(k)) * kPi * xyz[d];
        out[j] = (j & 1) ? std::sin(arg + kPi / 2) : std::sin(arg);
      }
      break;
    }
    case EncodingType::OneBlob: {
      const uint32_t nb = e.n_bins;
      const float fn = float(nb);
      for (uint32_t d = 0; d < 3; ++d) {
        auto C = [&](uint32_t b) {
          float t = float(b) / fn - xyz[d];
          return oneblob_q(t, fn) + oneblob_q(t - 1.0f, fn) + oneblob_q(t + 1.0f, fn);
        };
        for (uint32_t b = 0; b < nb; ++b)
          out[d * nb + b] = b + 1 < nb ? C(b + 1) - C(b) : C(0) + 1.0f - C(nb - 1);
      }
      break;
    }
    case EncodingType::Identity:
      for (int d = 0; d < 3; ++d) out[d] = xyz[d] * e.scale + e.offset;
      break;
  }
}

void Network::encode_point_input_grad(const float xyz[3], float* jac) const {
  const EncodingConfig& e = cfg_.encoding;
  const uint32_t w = mlp_.enc_width;
  std::fill(jac, jac + size_t(w) * 3, 0.0f);
  switch (e.type) {
    case EncodingType::Grid: {
      float tmp[8 * 3];
      for (uint32_t l = 0; l < grid_.n_levels; ++l) {
        const GridLevel& L = grid_.levels[l];
        switch (grid_.n_features) {
          case 1: grid_level_input_grad<1>(L, grid_.interpolation, grid_half(), xyz[0], xyz[1], xyz[2], tmp); break;
          case 2: grid_level_input_grad<2>(L, grid_.interpolation, grid_half(), xyz[0], xyz[1], xyz[2], tmp); break;
          case 4: grid_level_input_grad<4>(L, grid_.interpolation, grid_half(), xyz[0], xyz[1], xyz[2], tmp); break;
          case 8: grid_level_input_grad<8>(L, grid_.interpolation, grid_half(), xyz[0], xyz[1], xyz[2], tmp); break;
        }
        for (uint32_t f = 0; f < grid_.n_features; ++f)
          for (int d = 0; d < 3; ++d) jac[(l * grid_.n_features + f) * 3 + d] = tmp[f * 3 + d];
      }
      break;
    }
    case EncodingType::Frequency: {
      const uint32_t nf = e.n_frequencies;
      for (uint32_t j = 0; j < 3 * 2 * nf; ++j) {
        uint32_t d = j / (2 * nf), k = (j / 2) % nf;
        float a = std::ldexp(1.0f, int(k)) * kPi;
        jac[j * 3 + d] = (j & 1) ? -a * std::sin(a * xyz[d]) : a * std::cos(a * xyz[d]);
      }
      break;
    }
    case EncodingType::OneBlob: {
      const uint32_t nb = e.n_bins;
      const float fn = float(nb);
      for (uint32_t d = 0; d < 3; ++d) {
        auto dC = [&](uint32_t b) {  // d C(b) / d x
          float t = float(b) / fn - xyz[d];
          return -(oneblob_dq(t, fn) + oneblob_dq(t - 1.0f, fn) + oneblob_dq(t + 1.0f, fn));
        };
        for (uint32_t b = 0; b < nb; ++b)
          jac[(d * nb + b) * 3 + d] = b + 1 < nb ? dC(b + 1) - dC(b) : dC(0) - dC(nb - 1);
      }
      break;
    }
    case EncodingType::Identity:
      for (int d = 0; d < 3; ++d) jac[d * 3 + d] = e.scale;
      break;
  }
}

void Network::mlp_forward(const float* X0, int n, float* acts, float* out_pre, float* out) const {
  const MlpLayout& m = mlp_;
  const bool relu = m.activation == Activation::ReLU;
  const float* in = X0;
  for (uint32_t k = 0; k < m.n_hidden; ++k) {
    float* h = acts + size_t(k) * m.width * n;
    const int cols = k == 0 ? int(m.first_cols) : int(m.cols[k]);
    kernels::matmul_fwd(params.data() + m.offset[k], int(m.rows[k]), cols, in, h, n, relu, int(m.cols[k]));
    in = h;
  }
  // Output layer: only the n_out real rows are computed; tcnn's padded rows never reach the loss.
  kernels::matmul_fwd(params.data() + m.offset[m.n_hidden], int(m.n_out), int(m.width), in, out_pre, n, false);
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
  kernels::matmul_bwd_data(params.data() + m.offset[H], int(m.n_out), int(m.width), d_out_pre, relu ? hH : nullptr,
                           g_cur, n);
  for (uint32_t k = H - 1; k >= 1; --k) {
    const float* hk = acts + size_t(k - 1) * wn;  // input of matrix k
    kernels::matmul_bwd_weights(g_cur, int(m.width), hk, int(m.width), n, dW + m.offset[k]);
    kernels::matmul_bwd_data(params.data() + m.offset[k], int(m.width), int(m.width), g_cur, relu ? hk : nullptr,
                             g_next, n);
    std::swap(g_cur, g_next);
  }
  // Gradients of the zero-padded input columns are exactly 0 and not computed; dX0 rows past the
  // encoding width are not written (nothing reads them).
  const int k0 = int(m.first_cols);
  kernels::matmul_bwd_weights(g_cur, int(m.width), X0, k0, n, dW + m.offset[0], int(m.in_pad));
  if (dX0)
    kernels::matmul_bwd_data(params.data() + m.offset[0], int(m.width), k0, g_cur, nullptr, dX0, n, int(m.in_pad));
}

void Network::grid_backward_level(uint32_t level, const float* x, const float* y, const float* z, int64_t n,
                                  const float* dEnc, int chunk, float* grad) const {
  kernels::grid_backward_level(grid_, level, x, y, z, n, dEnc, mlp_.in_pad, chunk, grad);
}

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

std::vector<uint32_t> Network::bf16_weights() const {
  const MlpLayout& m = mlp_;
  const int kpw = int(m.width) / 2, kp0 = int(m.first_cols + 1) / 2;
  std::vector<uint32_t> wp(size_t(m.width) * kp0 + size_t(m.n_hidden - 1) * m.width * kpw + size_t(m.n_out) * kpw);
  uint32_t* w = wp.data();
  for (uint32_t k = 0; k <= m.n_hidden; ++k) {
    const int rows = k == m.n_hidden ? int(m.n_out) : int(m.width);
    const int K = k == 0 ? int(m.first_cols) : int(m.width);
    kernels::weights_to_bf16_pairs(params.data() + m.offset[k], rows, K, int(m.cols[k]), w);
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
    const float* Wk = params.data() + m.offset[k];
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

void Network::infer_chunk_bf16(const float* x, const float* y, const float* z, int n, float* out, float* ws,
                               const uint32_t* wp) const {
  float* X0 = ws;
  encode(x, y, z, n, X0);
  mlp_forward_bf16(X0, n, wp, reinterpret_cast<uint32_t*>(X0 + size_t(mlp_.in_pad) * n), out);
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
    for (uint32_t k = 1; k < m.n_hidden; ++k) Wh[k - 1] = params.data() + m.offset[k];
    kernels::mlp_forward_16(params.data() + m.offset[0], int(m.first_cols), int(m.in_pad), Wh, int(m.n_hidden - 1),
                            params.data() + m.offset[m.n_hidden], X0, n, pre);
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

float Network::eval_reference(float x, float y, float z) const {
  const MlpLayout& m = mlp_;
  std::vector<float> in(m.in_pad, m.pad_value), h;
  const float p[3] = {x, y, z};
  encode_point(p, in.data());
  for (uint32_t k = 0; k <= m.n_hidden; ++k) {
    uint64_t rows = k == m.n_hidden ? m.n_out : m.rows[k];
    h.assign(rows, 0.0f);
    const float* W = params.data() + m.offset[k];
    for (uint64_t r = 0; r < rows; ++r) {
      double acc = 0;
      for (uint64_t c = 0; c < m.cols[k]; ++c) acc += double(W[r * m.cols[k] + c]) * in[c];
      h[r] = k == m.n_hidden ? activate(m.output_activation, float(acc))
                             : (m.activation == Activation::ReLU ? std::max(0.0f, float(acc)) : float(acc));
    }
    in = h;
  }
  return in[0];
}

}  // namespace vnr
