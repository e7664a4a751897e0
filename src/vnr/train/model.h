#pragma once
// Model (vnr/model.h) with the complete types of its members, and the .vnr file it is written as.
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>
#include "vnr/model.h"
#include "vnr/core/value_range_grid.h"
#include "vnr/nn/model_file.h"
#include "vnr/nn/network.h"
#include "vnr/nn/param_codec.h"
#include "vnr/train/residuals.h"

namespace vnr {

// The .vnr file save_model writes for a single-network model.
ModelFile model_file(const Model& m);
// The file's description of m (config, dims, dtype, range, training summary, macro-cells) without the
// parameters, residuals or storage choices: save_model and the rate search fill those in.
ModelFile model_file_without_params(const Model& m);
}  // namespace vnr
