#pragma once
#include <cstdint>
#include "vnr/core/rng.h"
#include "vnr/volume/volume.h"

namespace vnr {

// Produces training samples: coordinates in [0,1)^3 (SoA) and normalised target values.
// sample() is called concurrently for disjoint chunks of one step; a chunk's samples depend only
// on (seed, step, chunk index), never on which thread runs it.
class Sampler {
public:
  virtual ~Sampler() = default;
  virtual void begin_step(uint64_t step) {}
  virtual void sample(uint64_t seed, uint64_t step, uint64_t chunk, int n, float* x, float* y, float* z,
                      float* target) const = 0;
};

// Uniform coordinates, cell-centred trilinear targets from a volume in memory (compat.md B.3).
class InCoreSampler : public Sampler {
public:
  explicit InCoreSampler(GridView grid) : grid_(grid) {}
  explicit InCoreSampler(const Volume& vol) : grid_(view_of(vol)) {}
  void sample(uint64_t seed, uint64_t step, uint64_t chunk, int n, float* x, float* y, float* z,
              float* target) const override;

private:
  GridView grid_;
};

// The RNG of one chunk of one step.
inline Pcg32 chunk_rng(uint64_t seed, uint64_t step, uint64_t chunk) {
  return Pcg32(seed * 0x9E3779B97F4A7C15ULL + step * 0xD1B54A32D192ED03ULL + 1, chunk);
}

}  // namespace vnr
