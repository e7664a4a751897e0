#include "vnr/train/sampler.h"

namespace vnr {

void InCoreSampler::sample(uint64_t seed, uint64_t step, uint64_t chunk, int n, float* x, float* y, float* z,
                           float* target) const {
  uniform_coordinates(seed, step, chunk, n, x, y, z);
  grid_lookup_batch(grid_, x, y, z, n, target);
}

}  // namespace vnr
