#pragma once
// Sizing a config to a target compression ratio (--target-ratio).
#include <cstdint>
#include <string>
#include "vnr/nn/config.h"

namespace vnr {

// Sizes the grid of `config` (log2_hashmap_size, and n_levels if needed) so the fp16 model is about
// volume_bytes / ratio. Returns the adjusted config; `note` describes the choice.
ModelConfig size_config_for_ratio(const ModelConfig& config, uint64_t volume_bytes, double ratio, std::string* note);

}  // namespace vnr
