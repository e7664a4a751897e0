#pragma once
// The MLP's parameter layout (docs/semantics.md A.4, A.5): padded input and output widths from the
// encoding and the network config, and each matrix's place in the flat parameter vector.
#include <cstdint>
#include "vnr/model_config.h"

namespace vnr {

struct MlpLayout {
  uint32_t enc_width = 0;  // encoding output width before padding
  uint32_t in_pad = 0;     // padded MLP input width
  float pad_value = 0;     // 0 for grids, 1 for parameter-free encodings (acts as a bias input)
  uint32_t first_cols = 0; // columns of W_0 that see real inputs: zero-padded ones (grids) are skipped
  uint32_t width = 0, n_hidden = 0;
  uint32_t n_out = 1, out_pad = 16;
  uint32_t n_matrices = 0;           // n_hidden + 1
  uint64_t offset[34], rows[34], cols[34];
  uint64_t n_params = 0;
  Activation activation = Activation::ReLU, output_activation = Activation::None;
};

MlpLayout make_mlp_layout(const ModelConfig& cfg, uint32_t n_output_dims = 1);

// Whether the padded input and the hidden width are multiples of 16, as the GPU's warp-cooperative
// in-shader MLP needs (it multiplies 16 x 16 tiles): FullyFusedMLP's are, a CutlassMLP's input is padded
// to 8 and its width is any.
inline bool mlp_in_16_wide_tiles(const MlpLayout& m) { return m.in_pad % 16 == 0 && m.width % 16 == 0; }

// Total parameter count of a config, without allocating the parameters.
uint64_t count_params(const ModelConfig& config, uint32_t n_output_dims = 1);

}  // namespace vnr
