// Batched ground-truth lookup (the grid side of the batched field query), compiled per SIMD target.
// Each lane computes exactly grid_lookup() of volume.h (same operations, same order), so the batch
// and the per-point function agree bit for bit; gathers keep many cache misses in flight.
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "vnr/volume/lookup_batch.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

#include "vnr/volume/volume.h"

HWY_BEFORE_NAMESPACE();
namespace vnr {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

void LookupBatch(const GridView& g, const float* x, const float* y, const float* z, int64_t n, float* out) {
  const hn::ScalableTag<float> df;
  const hn::RebindToSigned<decltype(df)> di;
  const int64_t N = int64_t(hn::Lanes(df));
  int64_t i = 0;
  // 32-bit gather indices cover volumes below 2^31 voxels; larger ones take the scalar path.
  if (uint64_t(g.nx) * uint64_t(g.ny) * uint64_t(g.nz) < (uint64_t(1) << 31)) {
    const float* in[3] = {x, y, z};
    const int32_t dims[3] = {g.nx, g.ny, g.nz};
    const auto half = hn::Set(df, 0.5f), zero = hn::Zero(df), one = hn::Set(df, 1.0f);
    const auto sy = hn::Set(di, g.nx), sz = hn::Set(di, g.nx * g.ny), ione = hn::Set(di, 1);
    // Prefetch the four x-rows of the next block's cells while this block gathers: the gathers are
    // latency-bound random reads, and Zen's gathers stall until all lanes arrive.
    auto prefetch_block = [&](int64_t b) {
      alignas(64) int32_t base[16];
      hn::Vec<decltype(di)> c[3];
      for (int d = 0; d < 3; ++d) {
        const auto nd = hn::Set(df, float(dims[d]));
        const auto p = hn::Sub(hn::Mul(hn::LoadU(df, in[d] + b), nd), half);
        c[d] = hn::ConvertTo(di, hn::Floor(hn::Min(hn::Max(p, zero), hn::Set(df, float(dims[d] - 1)))));
      }
      hn::StoreU(hn::Add(c[0], hn::Add(hn::Mul(c[1], sy), hn::Mul(c[2], sz))), di, base);
      const int64_t ry = g.nx, rz = int64_t(g.nx) * g.ny;
      for (int64_t l = 0; l < N; ++l) {
        const float* p0 = g.data + base[l];  // into L2 (prefetcht1), as the grid kernels do
        __builtin_prefetch(p0, 0, 2);
        __builtin_prefetch(p0 + ry, 0, 2);
        __builtin_prefetch(p0 + rz, 0, 2);
        __builtin_prefetch(p0 + ry + rz, 0, 2);
      }
    };
    // Prefetch kAhead blocks ahead: one block's gathers take about one memory latency.
    constexpr int64_t kAhead = 4;
    if (N <= 16)
      for (int64_t b = 0; b < kAhead && (b + 1) * N <= n; ++b) prefetch_block(b * N);
    for (; i + N <= n; i += N) {
      if (N <= 16 && i + (kAhead + 1) * N <= n) prefetch_block(i + kAhead * N);
      hn::Vec<decltype(di)> i0[3], i1[3];
      hn::Vec<decltype(df)> t[3];
      for (int d = 0; d < 3; ++d) {
        const auto nd = hn::Set(df, float(dims[d]));
        const auto p = hn::Sub(hn::Mul(hn::LoadU(df, in[d] + i), nd), half);
        const auto q = hn::Min(hn::Max(p, zero), hn::Set(df, float(dims[d] - 1)));
        const auto fl = hn::Floor(q);
        i0[d] = hn::ConvertTo(di, fl);
        i1[d] = hn::Min(hn::Add(i0[d], ione), hn::Set(di, dims[d] - 1));
        t[d] = hn::Sub(q, fl);
      }
      auto at = [&](const hn::Vec<decltype(di)>& cx, const hn::Vec<decltype(di)>& cy, const hn::Vec<decltype(di)>& cz) {
        return hn::GatherIndex(df, g.data, hn::Add(cx, hn::Add(hn::Mul(cy, sy), hn::Mul(cz, sz))));
      };
      const auto u0 = hn::Sub(one, t[0]), u1 = hn::Sub(one, t[1]), u2 = hn::Sub(one, t[2]);
      const auto c00 = hn::Add(hn::Mul(at(i0[0], i0[1], i0[2]), u0), hn::Mul(at(i1[0], i0[1], i0[2]), t[0]));
      const auto c10 = hn::Add(hn::Mul(at(i0[0], i1[1], i0[2]), u0), hn::Mul(at(i1[0], i1[1], i0[2]), t[0]));
      const auto c01 = hn::Add(hn::Mul(at(i0[0], i0[1], i1[2]), u0), hn::Mul(at(i1[0], i0[1], i1[2]), t[0]));
      const auto c11 = hn::Add(hn::Mul(at(i0[0], i1[1], i1[2]), u0), hn::Mul(at(i1[0], i1[1], i1[2]), t[0]));
      const auto c0 = hn::Add(hn::Mul(c00, u1), hn::Mul(c10, t[1]));
      const auto c1 = hn::Add(hn::Mul(c01, u1), hn::Mul(c11, t[1]));
      hn::StoreU(hn::Add(hn::Mul(c0, u2), hn::Mul(c1, t[2])), df, out + i);
    }
  }
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
