// The reference evaluation of one point: plain loops in double, for tests.
#include <algorithm>
#include <vector>
#include "vnr/nn/loss.h"
#include "vnr/nn/network.h"

namespace vnr {

float Network::eval_reference(float x, float y, float z) const {
  const MlpLayout& m = mlp_;
  std::vector<float> in(m.in_pad, m.pad_value), h;
  const float p[3] = {x, y, z};
  encode_point(p, in.data());
  for (uint32_t k = 0; k <= m.n_hidden; ++k) {
    uint64_t rows = k == m.n_hidden ? m.n_out : m.rows[k];
    h.assign(rows, 0.0f);
    const float* W = params_.data() + m.offset[k];
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
