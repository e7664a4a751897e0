#include "vnr/train/sampler.h"

namespace vnr {

void InCoreSampler::sample(uint64_t seed, uint64_t step, uint64_t chunk, int n, float* x, float* y, float* z,
                           float* target) const {
  Pcg32 rng = chunk_rng(seed, step, chunk);
  for (int i = 0; i < n; ++i) {
    x[i] = rng.next_float();
    y[i] = rng.next_float();
    z[i] = rng.next_float();
  }
  grid_lookup_batch(grid_, x, y, z, n, target);
}

}  // namespace vnr
