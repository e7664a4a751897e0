#pragma once
// Sizing a config to a byte budget (--target-ratio).
#include <cstdint>
#include <string>
#include "vnr/model_config.h"
#include "vnr/training_options.h"
#include "vnr/volume/volume.h"

namespace vnr {

// Compact storage (train/rate_control.h): sizes the grid so that the parameters at `bits_per_param`
// bits each (after quantization and entropy coding) take about target_bytes. The exact size is then
// met by the quantization steps. `note` describes the choice.
ModelConfig size_config_for_bytes(const ModelConfig& config, uint64_t target_bytes, double bits_per_param,
                                  std::string* note);

// The network of an error bound given alone (--max-error/--max-rel-error without --target-ratio, config
// auto): its file takes kBoundNetworkShare of the bytes the bound costs without a network
// (predictorless_bytes: the voxels quantised and coded as residuals are), at least 32 KiB for the
// config's network, or the small preset's of at least 2 KiB where the share is under 32 KiB; as a
// target ratio of source_bytes, at most 1024; network_ratio 0 (no sizing) when that leaves no ratio
// above 1. docs/COMPRESSION.md has the runs that fitted the share. `bound` is normalised.
constexpr double kBoundNetworkShare = 0.1;
constexpr double kConfigNetworkFloorBytes = 32768, kSmallNetworkFloorBytes = 2048;
// A network beside residuals: its target ratio (0: no residuals) and whether it is the small preset's.
struct ResidualSplit {
  double network_ratio = 0;    // the network's target ratio; 0: no residuals
  bool small_network = false;  // the small preset's network instead of the config's
};
ResidualSplit bounded_network_split(const Volume& vol, uint64_t source_bytes, double bound, std::string* note);

// --target-ratio R alone with --residuals auto: residuals (wavelet or voxel, train/residuals.h) decode
// closer than a network of the whole file, so the network gets kResidualNetworkShare of the file, enough to
// render and answer point queries on its own, and the residuals the rest. The config's network needs
// kConfigNetworkFloorBytes (a compact paper MLP fits); where a tenth is less and the config is `auto`,
// the small preset's network (MLP 16 x 2) takes it instead, at least kSmallNetworkFloorBytes (a model
// file's coded header, macro-cells and zero parameters take ~0.7 KB of it); a network
// over kResidualNetworkMaxShare of the file leaves no residuals (network_ratio 0: it takes the file).
// docs/COMPRESSION.md has the runs that fitted it.
constexpr double kResidualNetworkShare = 0.1, kResidualNetworkMaxShare = 0.5;
ResidualSplit residual_network_split(uint64_t source_bytes, uint64_t voxels, double target_ratio, bool config_is_auto,
                                     std::string* note);

}  // namespace vnr
