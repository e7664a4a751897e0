#include "vnr/train/sampler.h"

namespace vnr {

void uniform_coordinates(uint64_t seed, uint64_t step, uint64_t chunk, int n, float* x, float* y, float* z) {
  // Four independent pcg32 streams (x, y, z of every 4th sample each) so the LCG multiply chains
  // run in parallel instead of one after another.
  constexpr int kStreams = kCoordinateStreams;  // uniform_sample_coordinate() is the per-sample form
  Pcg32 rng[kStreams];
  for (int j = 0; j < kStreams; ++j) rng[j] = chunk_rng(seed, step, chunk * kStreams + uint64_t(j));
  int i = 0;
  for (; i + kStreams <= n; i += kStreams)
    for (int j = 0; j < kStreams; ++j) {
      x[i + j] = rng[j].next_float();
      y[i + j] = rng[j].next_float();
      z[i + j] = rng[j].next_float();
    }
  for (; i < n; ++i) {
    x[i] = rng[0].next_float();
    y[i] = rng[0].next_float();
    z[i] = rng[0].next_float();
  }
}

void InCoreSampler::sample(uint64_t seed, uint64_t step, uint64_t chunk, int n, float* x, float* y, float* z,
                           float* target) const {
  uniform_coordinates(seed, step, chunk, n, x, y, z);
  grid_lookup_batch(grid_, x, y, z, n, target);
}

}  // namespace vnr
