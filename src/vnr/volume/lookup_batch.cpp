// Batched ground-truth lookup (the grid side of the batched field query), compiled per SIMD target.
// Each lane computes exactly grid_lookup() of vnr/grid_view.h (same operations, same order), so the batch
// and the per-point function agree bit for bit; gathers keep many cache misses in flight.
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "vnr/volume/lookup_batch.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

#include "vnr/volume/lookup-inl.h"
#include "vnr/volume/volume.h"

HWY_BEFORE_NAMESPACE();
namespace vnr {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// Points [0, n - n % lanes) of LookupBatch, with or without x-neighbour pairs.
template <bool kPairs>
int64_t LookupBlocks(const GridView& g, const float* x, const float* y, const float* z, int64_t n, float* out) {
  const hn::ScalableTag<float> df;
  const int64_t N = int64_t(hn::Lanes(df));
  auto prefetch_block = [&](int64_t b) {
    GridPrefetchVec(df, g, hn::LoadU(df, x + b), hn::LoadU(df, y + b), hn::LoadU(df, z + b));
  };
  // Prefetch kAhead blocks ahead: one block's gathers take about one memory latency, which the
  // prefetches hide behind the blocks before it.
  constexpr int64_t kAhead = 4;
  for (int64_t b = 0; b < kAhead && (b + 1) * N <= n; ++b) prefetch_block(b * N);
  int64_t i = 0;
  for (; i + N <= n; i += N) {
    if (i + (kAhead + 1) * N <= n) prefetch_block(i + kAhead * N);
    hn::StoreU(GridLookupVec<kPairs>(df, g, hn::LoadU(df, x + i), hn::LoadU(df, y + i), hn::LoadU(df, z + i)), df,
               out + i);
  }
  return i;
}

void LookupBatch(const GridView& g, const float* x, const float* y, const float* z, int64_t n, float* out) {
  int64_t i = 0;
  // 32-bit gather indices cover volumes below 2^31 voxels; larger ones take the scalar path. From 2
  // voxels in x up, x-neighbours load as one 64-bit element.
  if (grid_fits_gather_indices(g))
    i = g.nx >= 2 ? LookupBlocks<true>(g, x, y, z, n, out) : LookupBlocks<false>(g, x, y, z, n, out);
  for (; i < n; ++i) out[i] = grid_lookup(g, x[i], y[i], z[i]);
}

}  // namespace HWY_NAMESPACE
}  // namespace vnr
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace vnr {
HWY_EXPORT(LookupBatch);
void grid_lookup_batch(const GridView& g, const float* x, const float* y, const float* z, int64_t n, float* out) {
  HWY_DYNAMIC_DISPATCH(LookupBatch)(g, x, y, z, n, out);
}
}  // namespace vnr
#endif
