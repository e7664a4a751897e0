#pragma once
#include <cstdint>
#include "vnr/core/rng.h"
#include "vnr/volume/volume.h"

namespace vnr {

// Produces training samples: coordinates in [0,1)^3 (SoA) and normalised target values.
// begin_step() runs on one thread before a step's samples are drawn (samplers that stream data
// do their bookkeeping there); sample() is then called concurrently for disjoint chunks of the
// step, and a chunk's samples depend only on (seed, step, chunk index), never on which thread
// runs it.
class Sampler {
public:
  virtual ~Sampler() = default;
  virtual void begin_step(uint64_t step) {}
  virtual void sample(uint64_t seed, uint64_t step, uint64_t chunk, int n, float* x, float* y, float* z,
                      float* target) const = 0;
};

// An integer in [0, n) from one draw (multiply-shift; the bias is below n / 2^32).
VNR_HD inline uint32_t rng_below(Pcg32& rng, uint32_t n) { return uint32_t((uint64_t(rng.next_uint()) * n) >> 32); }

// Uniform coordinates in [0,1)^3 for one chunk (docs/semantics.md B.3), shared by every sampler that
// draws positions uniformly over the whole volume.
void uniform_coordinates(uint64_t seed, uint64_t step, uint64_t chunk, int n, float* x, float* y, float* z);

// Uniform coordinates, cell-centred trilinear targets from a volume in memory (docs/semantics.md B.3).
class InCoreSampler : public Sampler {
public:
  explicit InCoreSampler(GridView grid) : grid_(grid) {}
  explicit InCoreSampler(const Volume& vol) : grid_(view_of(vol)) {}
  void sample(uint64_t seed, uint64_t step, uint64_t chunk, int n, float* x, float* y, float* z,
              float* target) const override;

private:
  GridView grid_;
};

}  // namespace vnr
