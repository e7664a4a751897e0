#include "vnr/train/config_sizing.h"
#include <algorithm>
#include <cmath>
#include "vnr/error.h"
#include "vnr/nn/mlp_layout.h"
#include "vnr/train/residuals.h"

namespace vnr {

ModelConfig size_config_for_bytes(const ModelConfig& base, uint64_t target_bytes, double bits_per_param,
                                  std::string* note) {
  if (!(bits_per_param > 0 && bits_per_param <= 16)) fail("bits per parameter must be in (0, 16], got {}", bits_per_param);
  if (base.encoding.type != EncodingType::Grid || base.encoding.grid_type != GridType::Hash)
    fail("--target-ratio needs a HashGrid encoding (the config has {})", base.to_json()["encoding"]["otype"].dump());
  const double target_params = double(target_bytes) * 8.0 / bits_per_param;
  ModelConfig best = base;
  double best_err = 1e300;
  uint64_t best_params = 0;
  const uint32_t L0 = base.encoding.n_levels;
  for (uint32_t L = L0; L >= 1; --L)
    for (uint32_t t = 6; t <= 24; ++t) {
      ModelConfig c = base;
      c.encoding.n_levels = L;
      c.encoding.log2_hashmap_size = t;
      const uint64_t n = count_params(c);
      // Keep every level while the table can shrink instead: a dropped level costs like a factor 1.5.
      const double err = std::fabs(std::log(double(n) / target_params)) + 0.4 * (L0 - L);
      if (err < best_err) best_err = err, best = c, best_params = n;
    }
  if (note)
    *note = fmt::format("compact model: {} levels, 2^{} table, {} parameters for {} bytes (~{:.1f} bits each)",
                        best.encoding.n_levels, best.encoding.log2_hashmap_size, best_params, target_bytes,
                        double(target_bytes) * 8.0 / double(best_params));
  return best;
}

namespace {
// The network of `share` bytes beside residuals: the config's where the share is at least its floor,
// else (config auto) the small preset's, at least its floor; *bytes is what it is given.
ResidualSplit network_for_share(double share, bool config_is_auto, double* bytes) {
  ResidualSplit split;
  split.small_network = share < kConfigNetworkFloorBytes && config_is_auto;
  *bytes = std::max(share, split.small_network ? kSmallNetworkFloorBytes : kConfigNetworkFloorBytes);
  return split;
}
}  // namespace

ResidualSplit bounded_network_split(const Volume& vol, uint64_t source_bytes, double bound, std::string* note) {
  const uint64_t without = predictorless_bytes(vol.data.data(), vol.dims, bound);
  double budget = 0;
  ResidualSplit split = network_for_share(kBoundNetworkShare * double(without), true, &budget);
  split.network_ratio = std::min(double(source_bytes) / budget, 1024.0);
  if (split.network_ratio <= 1) {
    if (note) *note = "error bound alone: the volume is too small to size a network for it; the config's network is used";
    return {};
  }
  if (note)
    *note = fmt::format("error bound alone: without a network it costs {} bytes ({:.2f}x); the {}network gets {:.0f} % "
                        "of that: --target-ratio {:.3g}", without, double(source_bytes) / double(std::max<uint64_t>(without, 1)),
                        split.small_network ? "small preset's " : "", 100 * budget / double(std::max<uint64_t>(without, 1)),
                        split.network_ratio);
  return split;
}

ResidualSplit residual_network_split(uint64_t source_bytes, uint64_t voxels, double target_ratio, bool config_is_auto,
                                     std::string* note) {
  const double budget = double(source_bytes) / target_ratio, bits_per_voxel = 8 * budget / double(voxels);
  double network = 0;
  ResidualSplit split = network_for_share(kResidualNetworkShare * budget, config_is_auto, &network);
  if (network > kResidualNetworkMaxShare * budget) return split;
  split.network_ratio = double(source_bytes) / network;
  if (note)
    *note = fmt::format("--residuals auto: {:.2f} bits per voxel; the {}network gets {:.0f} % of the file (ratio {:.3g}), "
                        "wavelet or voxel residuals the rest", bits_per_voxel, split.small_network ? "small preset's " : "",
                        100 * network / budget, split.network_ratio);
  return split;
}

}  // namespace vnr
