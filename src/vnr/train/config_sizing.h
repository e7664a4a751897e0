#pragma once
// Sizing a config to a byte budget (--target-ratio).
#include <cstdint>
#include <string>
#include "vnr/nn/config.h"

namespace vnr {

// Compact storage (train/rate_control.h): sizes the grid so that the parameters at `bits_per_param`
// bits each (after quantization and entropy coding) take about target_bytes. The exact size is then
// met by the quantization steps. `note` describes the choice.
constexpr double kDefaultBitsPerParam = 4.0;
ModelConfig size_config_for_bytes(const ModelConfig& config, uint64_t target_bytes, double bits_per_param,
                                  std::string* note);

}  // namespace vnr
