#pragma once
#include <cstdint>
#include "vnr/hd.h"

namespace vnr {

// PCG-XSH-RR 64/32 with tiny-cuda-nn's seeding and next_float (docs/semantics.md A.8).
struct Pcg32 {
  static constexpr uint64_t kMult = 0x5851F42D4C957F2DULL;
  uint64_t state = 0x853c49e6748fea9bULL;
  uint64_t inc = 0xda3e39cb94b95bdbULL;

  Pcg32() = default;  // (defaulted: host and device alike)
  VNR_HD explicit Pcg32(uint64_t initstate, uint64_t initseq = 1u) { seed(initstate, initseq); }
  VNR_HD void seed(uint64_t initstate, uint64_t initseq = 1u) {
    state = 0u;
    inc = (initseq << 1u) | 1u;
    next_uint();
    state += initstate;
    next_uint();
  }
  VNR_HD uint32_t next_uint() {
    uint64_t old = state;
    state = old * kMult + inc;
    uint32_t xorshifted = uint32_t(((old >> 18u) ^ old) >> 27u);
    uint32_t rot = uint32_t(old >> 59u);
    return (xorshifted >> rot) | (xorshifted << ((~rot + 1u) & 31));
  }
  VNR_HD float next_float() {
    union { uint32_t u; float f; } x;
    x.u = (next_uint() >> 9) | 0x3f800000u;
    return x.f - 1.0f;
  }
  // Jump ahead by delta steps in O(log delta) (Brown, "Random number generation with arbitrary stride").
  VNR_HD void advance(uint64_t delta) {
    uint64_t cur_mult = kMult, cur_plus = inc, acc_mult = 1u, acc_plus = 0u;
    while (delta > 0) {
      if (delta & 1) {
        acc_mult *= cur_mult;
        acc_plus = acc_plus * cur_mult + cur_plus;
      }
      cur_plus = (cur_mult + 1) * cur_plus;
      cur_mult *= cur_mult;
      delta /= 2;
    }
    state = acc_mult * state + acc_plus;
  }
};

// The RNG of one chunk of one training step (every backend's samplers draw from it).
VNR_HD inline Pcg32 chunk_rng(uint64_t seed, uint64_t step, uint64_t chunk) {
  return Pcg32(seed * 0x9E3779B97F4A7C15ULL + step * 0xD1B54A32D192ED03ULL + 1, chunk);
}

// Uniform training coordinates: sample i of an n-sample chunk draws x, y, z from stream i % 4 of
// the chunk (4 streams, so the CPU's LCG chains run side by side), the last n % 4 samples from
// stream 0. One sample at a time (GPU threads) with advance(); the CPU's uniform_coordinates()
// draws the same numbers stream by stream (tested equal).
constexpr int kCoordinateStreams = 4;
VNR_HD inline void uniform_sample_coordinate(uint64_t seed, uint64_t step, uint64_t chunk, int n, int i, float* x,
                                             float* y, float* z) {
  const int n4 = n / kCoordinateStreams * kCoordinateStreams;
  const int stream = i < n4 ? i % kCoordinateStreams : 0;
  const uint64_t skip = i < n4 ? uint64_t(i / kCoordinateStreams) : uint64_t(n4 / kCoordinateStreams + (i - n4));
  Pcg32 rng = chunk_rng(seed, step, chunk * kCoordinateStreams + uint64_t(stream));
  rng.advance(3 * skip);
  *x = rng.next_float();
  *y = rng.next_float();
  *z = rng.next_float();
}

// tiny-cuda-nn seeds its trainer RNG with std::seed_seq{seed}.generate(2 words)[0].
uint32_t seed_seq_first_word(uint32_t seed);

}  // namespace vnr
