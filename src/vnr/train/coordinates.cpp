// uniform_coordinates() per SIMD target (Highway's foreach_target, chosen at run time).
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "vnr/train/coordinates.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

#include "vnr/core/rng.h"
#include "vnr/train/sampler.h"

HWY_BEFORE_NAMESPACE();
namespace vnr {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// Draws of the four streams, sample by sample: stream j gives x, y, z of samples 4t + j.
void ScalarCoordinates(Pcg32* rng, int i, int n, float* x, float* y, float* z) {
  constexpr int kStreams = kCoordinateStreams;
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

#if HWY_TARGET <= HWY_AVX3
// 64-bit lane k (k < 8) holds stream k % 4 at its sample slot t + k / 4, so one vector step emits
// samples 8u .. 8u + 7 in order. The y and z draws and the next state are affine maps of the
// state (LCG jump-ahead: s -> s*A + C), computed side by side instead of as a multiply chain.
// Every lane computes exactly Pcg32::next_float, so the numbers are the scalar ones.
HWY_INLINE hn::Vec<hn::Half<hn::ScalableTag<float>>> Draw(hn::Vec<hn::ScalableTag<uint64_t>> old) {
  const hn::ScalableTag<uint64_t> du64;
  const hn::Half<hn::ScalableTag<uint32_t>> du32;
  const hn::Half<hn::ScalableTag<float>> df;
  const auto lo32 = hn::Set(du64, 0xFFFFFFFFull);
  const auto xs = hn::And(hn::ShiftRight<27>(hn::Xor(hn::ShiftRight<18>(old), old)), lo32);
  const auto rot = hn::ShiftRight<59>(old);
  const auto r = hn::And(hn::Or(hn::Shr(xs, rot), hn::Shl(xs, hn::Sub(hn::Set(du64, 32), rot))), lo32);
  const auto bits = hn::Or(hn::ShiftRight<9>(hn::TruncateTo(du32, r)), hn::Set(du32, 0x3f800000u));
  return hn::Sub(hn::BitCast(df, bits), hn::Set(df, 1.0f));
}
#endif

void UniformCoordinates(uint64_t seed, uint64_t step, uint64_t chunk, int n, float* x, float* y, float* z) {
  constexpr int kStreams = kCoordinateStreams;
  Pcg32 rng[kStreams];
  for (int j = 0; j < kStreams; ++j) rng[j] = chunk_rng(seed, step, chunk * kStreams + uint64_t(j));
  int i = 0;
#if HWY_TARGET <= HWY_AVX3
  const hn::ScalableTag<uint64_t> du64;
  const hn::Half<hn::ScalableTag<float>> df;
  static_assert(kStreams == 4, "two sample slots of the four streams per 512-bit vector");
  if (hn::Lanes(du64) == 8 && n >= 8) {
    // Jump-ahead maps, s -> s * M^d + C_d after d draws: Pcg32::advance from state 1 without
    // increment gives M^d, from state 0 with the stream's increment C_d.
    auto jump = [](uint64_t state, uint64_t inc, uint64_t d) {
      Pcg32 r;
      r.state = state;
      r.inc = inc;
      r.advance(d);
      return r.state;
    };
    alignas(64) uint64_t s0[8], c1[8], c2[8], c6[8];
    for (int k = 0; k < 8; ++k) {
      const Pcg32& r = rng[k % 4];
      s0[k] = k < 4 ? r.state : jump(r.state, r.inc, 3);  // slot t + 1: three draws later
      c1[k] = jump(0, r.inc, 1);
      c2[k] = jump(0, r.inc, 2);
      c6[k] = jump(0, r.inc, 6);
    }
    const auto m1 = hn::Set(du64, jump(1, 0, 1)), m2 = hn::Set(du64, jump(1, 0, 2)), m6 = hn::Set(du64, jump(1, 0, 6));
    const auto C1 = hn::Load(du64, c1), C2 = hn::Load(du64, c2), C6 = hn::Load(du64, c6);
    auto s = hn::Load(du64, s0);
    for (; i + 8 <= n; i += 8) {
      const auto sy = hn::Add(hn::Mul(s, m1), C1), sz = hn::Add(hn::Mul(s, m2), C2);
      hn::StoreU(Draw(s), df, x + i);
      hn::StoreU(Draw(sy), df, y + i);
      hn::StoreU(Draw(sz), df, z + i);
      s = hn::Add(hn::Mul(s, m6), C6);
    }
    hn::Store(s, du64, s0);
    for (int j = 0; j < kStreams; ++j) rng[j].state = s0[j];  // lanes 0-3: each stream's next draw
  }
#endif
  ScalarCoordinates(rng, i, n, x, y, z);
}

}  // namespace HWY_NAMESPACE
}  // namespace vnr
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace vnr {
HWY_EXPORT(UniformCoordinates);
void uniform_coordinates(uint64_t seed, uint64_t step, uint64_t chunk, int n, float* x, float* y, float* z) {
  HWY_DYNAMIC_DISPATCH(UniformCoordinates)(seed, step, chunk, n, x, y, z);
}
}  // namespace vnr
#endif
