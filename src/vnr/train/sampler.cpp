#include "vnr/train/sampler.h"

namespace vnr {

InCoreSampler::InCoreSampler(GridView grid, uint64_t zpair_max_bytes) : grid_(grid) {
  const uint64_t voxels = uint64_t(grid.nx) * uint64_t(grid.ny) * uint64_t(grid.nz);
  if (grid.nx >= 2 && ZPairGrid::fits(grid) && 2 * sizeof(float) * voxels <= zpair_max_bytes)
    zpair_ = std::make_unique<ZPairGrid>(grid);
}

void InCoreSampler::sample(uint64_t seed, uint64_t step, uint64_t chunk, int n, float* x, float* y, float* z,
                           float* target) const {
  uniform_coordinates(seed, step, chunk, n, x, y, z);
  if (zpair_) grid_lookup_zpair_batch(*zpair_, x, y, z, n, target);
  else grid_lookup_batch(grid_, x, y, z, n, target);
}

}  // namespace vnr
