#include "vnr/nn/mlp_layout.h"
#include <numeric>
#include "vnr/math.h"
#include "vnr/nn/encoding.h"

namespace vnr {

MlpLayout make_mlp_layout(const ModelConfig& cfg, uint32_t n_output_dims) {
  MlpLayout m;
  const NetworkConfig& nc = cfg.network;
  const uint32_t align = nc.fully_fused ? 16u : 8u;
  const std::unique_ptr<Encoding> enc = make_encoding(cfg.encoding);
  m.enc_width = enc->output_width();
  m.in_pad = uint32_t(next_multiple(m.enc_width, std::lcm(align, enc->min_alignment())));
  m.pad_value = enc->pad_value();
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
  return make_mlp_layout(c, n_output_dims).n_params + make_encoding(c.encoding)->n_params();
}

}  // namespace vnr
