#include "vnr/nn/grid_encoding.h"
#include <algorithm>
#include "vnr/error.h"
#include "vnr/math.h"

namespace vnr {

GridLayout make_grid_layout(const EncodingConfig& cfg) {
  GridLayout g;
  g.n_levels = cfg.n_levels;
  g.n_features = cfg.n_features_per_level;
  g.interpolation = cfg.interpolation;
  const float log2s = log2f(cfg.per_level_scale);
  uint64_t offset = 0;
  for (uint32_t l = 0; l < cfg.n_levels; ++l) {
    GridLevel& L = g.levels[l];
    L.scale = exp2f(float(l) * log2s) * float(cfg.base_resolution) - 1.0f;
    // Beyond 2^30 cells per axis the uint32 resolution and the hashing of corners overflow.
    if (!(L.scale < 1073741824.0f))
      fail("encoding: level {} has a resolution of {} cells per axis (base_resolution {}, per_level_scale {}); at "
           "most 2^30 allowed", l, L.scale, cfg.base_resolution, cfg.per_level_scale);
    L.res = uint32_t(ceilf(L.scale)) + 1;
    double dense_f = double(L.res) * L.res * L.res;
    uint64_t dense = dense_f > 2147483647.0 ? 2147483647ull : uint64_t(L.res) * L.res * L.res;
    uint64_t n = next_multiple(dense, 8);
    if (cfg.grid_type == GridType::Hash) n = std::min<uint64_t>(n, 1ull << cfg.log2_hashmap_size);
    if (cfg.grid_type == GridType::Tiled)
      n = std::min<uint64_t>(n, uint64_t(cfg.base_resolution) * cfg.base_resolution * cfg.base_resolution);
    L.n_entries = uint32_t(n);
    L.hashed = (cfg.grid_type == GridType::Hash && dense_f > double(n)) ? 1u : 0u;
    L.pow2_mask = (n & (n - 1)) == 0 ? uint32_t(n - 1) : 0u;
    if (offset + n > 0xffffffffull) fail("encoding: the grid has more than 2^32 entries; reduce levels or table size");
    L.offset = uint32_t(offset);
    offset += n;
  }
  g.n_entries = offset;
  return g;
}

}  // namespace vnr
