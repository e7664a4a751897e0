#include "vnr/nn/network.h"
#include <algorithm>
#include <cmath>
#include "vnr/error.h"
#include "vnr/core/half.h"
#include "vnr/core/rng.h"
#include "vnr/units.h"
#include "vnr/nn/optimizer.h"

namespace vnr {

namespace {

// A config or model file may describe any number of parameters: refuse what cannot fit before
// allocating (fp32 master copy + fp16 table), naming the sizes.
void check_params_fit(uint64_t n_params, uint64_t grid_params) {
  const double bytes = double(n_params) * sizeof(float) + double(grid_params) * sizeof(uint16_t);
  const uint64_t available = available_memory_bytes();
  if (bytes <= double(available)) return;
  fail("the model has {} parameters ({} in the grid table) = {} exceeding the memory available ({}); reduce "
       "n_levels, log2_hashmap_size or the grid resolution",
       n_params, grid_params, human_bytes(bytes), human_bytes(double(available)));
}

}  // namespace

Network::Network(const ModelConfig& config, uint32_t n_output_dims)
    : cfg_(config), cfg_json_(cfg_.to_json()), enc_(make_encoding(cfg_.encoding)) {  // cfg_json_: every key explicit
  if (enc_->grid()) grid_ = *enc_->grid();
  mlp_ = make_mlp_layout(cfg_, n_output_dims);
  check_params_fit(n_params(), grid_params());
  params_.assign(n_params(), 0.0f);
  grid_half_.assign(grid_params(), 0);
}

void Network::sync_half_table() { floats_to_halves(grid_table(), grid_half_.data(), grid_params()); }

void Network::set_params(const float* values, size_t n) {
  if (n != params_.size()) fail("{} parameters for a network of {}", n, params_.size());
  edit_params([&](float* p, size_t) { std::copy_n(values, n, p); });
}

void Network::adam_step(Adam& adam, float* grads) {
  adam.step(params_.data(), grads, has_grid() ? grid_half_.data() : nullptr);
}

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
    float* w = params_.data() + mlp_.offset[k];
    for (uint64_t i = 0; i < mlp_.rows[k] * mlp_.cols[k]; ++i) w[i] = rng.next_float() * 2.0f * b - b;
  }
  if (!has_grid()) return;
  tcnn_uniform_fill(rng, grid_table_mut(), grid_params(), -1e-4f, 1e-4f);
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
  std::vector<uint16_t> h(params_.size());
  floats_to_halves(params_.data(), h.data(), h.size());
  return h;
}

void Network::set_params_half(const std::vector<uint16_t>& h) {
  if (h.size() != params_.size())
    fail("model has {} parameters but its configuration needs {}", h.size(), params_.size());
  halves_to_floats(h.data(), params_.data(), h.size());
  std::copy(h.begin() + int64_t(mlp_.n_params), h.end(), grid_half_.begin());
}

void Network::encode(const float* x, const float* y, const float* z, int n, float* X0) const {
  const MlpLayout& m = mlp_;
  enc_->forward(x, y, z, n, grid_half(), X0);
  for (uint32_t j = m.enc_width; j < m.in_pad; ++j)
    for (int s = 0; s < n; ++s) X0[size_t(j) * n + s] = m.pad_value;
}

void Network::encode_point(const float xyz[3], float* out) const { enc_->encode_point(xyz, grid_half(), out); }

void Network::encode_point_input_grad(const float xyz[3], float* jac) const {
  enc_->encode_point_input_grad(xyz, grid_half(), jac);
}

void Network::grid_backward_level(uint32_t level, const float* x, const float* y, const float* z, int64_t n,
                                  const float* dEnc, int chunk, float* grad) const {
  enc_->backward(level, x, y, z, n, dEnc, mlp_.in_pad, chunk, grad);
}

}  // namespace vnr
