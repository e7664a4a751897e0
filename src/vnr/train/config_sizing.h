#pragma once
// Sizing a config to a byte budget (--target-ratio).
#include <cstdint>
#include <string>
#include "vnr/nn/config.h"
#include "vnr/volume/volume.h"

namespace vnr {

// Compact storage (train/rate_control.h): sizes the grid so that the parameters at `bits_per_param`
// bits each (after quantization and entropy coding) take about target_bytes. The exact size is then
// met by the quantization steps. `note` describes the choice.
constexpr double kDefaultBitsPerParam = 4.0;
ModelConfig size_config_for_bytes(const ModelConfig& config, uint64_t target_bytes, double bits_per_param,
                                  std::string* note);

// The network of an error bound given alone (--max-error/--max-rel-error without --target-ratio): its
// file takes kBoundNetworkShare of the bytes the bound costs without a network (predictorless_bytes:
// the voxels quantised and coded as residuals are), at least 32 KiB (a compact file of the paper's MLP
// fits), as a target ratio of source_bytes, at most 1024; 0 (no sizing) when that leaves no ratio above
// 1. docs/COMPRESSION.md has the runs that fitted the share. `bound` is normalised.
constexpr double kBoundNetworkShare = 0.1;
double bounded_network_ratio(const Volume& vol, uint64_t source_bytes, double bound, std::string* note);

// --target-ratio R alone with --residuals auto: a network of kResidualNetworkBitsPerVoxel (at least 32 KiB)
// and residuals in the rest of the file (train/residuals.h: the finest bound that fits) decode better
// than a network of the whole file, where that network takes at most half of it; the ratio of that
// network, or 0 (the network takes the file). docs/COMPRESSION.md has the runs that fitted it.
constexpr double kResidualNetworkBitsPerVoxel = 0.1;
double residual_network_ratio(uint64_t source_bytes, uint64_t voxels, double target_ratio, std::string* note);

}  // namespace vnr
