// grid_lookup() of vnr/grid_view.h for a vector of points, per SIMD target (Highway's -inl.h convention:
// include it after <hwy/highway.h> inside a foreach_target translation unit). Each lane performs
// exactly the scalar operations in the same order, so the result agrees with grid_lookup bit for bit.
// Needs a volume below 2^31 voxels (32-bit gather indices): check grid_fits_gather_indices().
#if defined(VNR_VOLUME_LOOKUP_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef VNR_VOLUME_LOOKUP_INL_H_
#undef VNR_VOLUME_LOOKUP_INL_H_
#else
#define VNR_VOLUME_LOOKUP_INL_H_
#endif

#include <hwy/highway.h>
#include "vnr/core/gather-inl.h"
#include "vnr/volume/volume.h"

HWY_BEFORE_NAMESPACE();
namespace vnr {
namespace HWY_NAMESPACE {

// cell_axis()'s clamped position along one axis: q = u*N - 0.5 clamped to [0, N-1] (x86 max returns
// its second operand for a NaN lane: NaN -> 0, as the scalar code). q >= 0, so floor = truncation.
template <class DF>
HWY_INLINE hwy::HWY_NAMESPACE::Vec<DF> CellAxisPos(DF df, hwy::HWY_NAMESPACE::Vec<DF> u, int32_t n) {
  namespace hn = hwy::HWY_NAMESPACE;
  const auto p = hn::Sub(hn::Mul(u, hn::Set(df, float(n))), hn::Set(df, 0.5f));
  return hn::Min(hn::Max(p, hn::Zero(df)), hn::Set(df, float(n - 1)));
}

// Prefetches (into L2, prefetcht1) the four x-rows the grid lookups at (ux, uy, uz) will read. The
// lookups are latency-bound, and Zen's gathers stall until all lanes arrive.
template <class DF>
HWY_INLINE void GridPrefetchVec(DF df, const GridView& g, hwy::HWY_NAMESPACE::Vec<DF> ux,
                                hwy::HWY_NAMESPACE::Vec<DF> uy, hwy::HWY_NAMESPACE::Vec<DF> uz) {
  namespace hn = hwy::HWY_NAMESPACE;
  const hn::RebindToSigned<DF> di;
  constexpr size_t kMaxLanes = HWY_MAX_BYTES / sizeof(float);
  const auto cx = hn::ConvertTo(di, CellAxisPos(df, ux, g.nx)), cy = hn::ConvertTo(di, CellAxisPos(df, uy, g.ny)),
             cz = hn::ConvertTo(di, CellAxisPos(df, uz, g.nz));
  alignas(HWY_MAX_BYTES) int32_t voxel[kMaxLanes];
  hn::Store(hn::Add(cx, hn::Add(hn::Mul(cy, hn::Set(di, g.nx)), hn::Mul(cz, hn::Set(di, g.nx * g.ny)))), di, voxel);
  const int64_t ry = g.nx, rz = int64_t(g.nx) * g.ny;
  for (size_t l = 0; l < hn::Lanes(df); ++l) {
    const float* p0 = g.data + voxel[l];
    __builtin_prefetch(p0, 0, 2);
    __builtin_prefetch(p0 + ry, 0, 2);
    __builtin_prefetch(p0 + rz, 0, 2);
    __builtin_prefetch(p0 + ry + rz, 0, 2);
  }
}

// trilinear_corners() per lane: the 8 corners v[x + 2y + 4z], the upper corners' weights t per axis.
template <class DF>
HWY_INLINE hwy::HWY_NAMESPACE::Vec<DF> TrilinearCornersVec(DF df, const hwy::HWY_NAMESPACE::Vec<DF>* v,
                                                           const hwy::HWY_NAMESPACE::Vec<DF>* t) {
  namespace hn = hwy::HWY_NAMESPACE;
  const auto one = hn::Set(df, 1.0f);
  const auto u0 = hn::Sub(one, t[0]), u1 = hn::Sub(one, t[1]), u2 = hn::Sub(one, t[2]);
  const auto c00 = hn::Add(hn::Mul(v[0], u0), hn::Mul(v[1], t[0]));
  const auto c10 = hn::Add(hn::Mul(v[2], u0), hn::Mul(v[3], t[0]));
  const auto c01 = hn::Add(hn::Mul(v[4], u0), hn::Mul(v[5], t[0]));
  const auto c11 = hn::Add(hn::Mul(v[6], u0), hn::Mul(v[7], t[0]));
  const auto c0 = hn::Add(hn::Mul(c00, u1), hn::Mul(c10, t[1]));
  const auto c1 = hn::Add(hn::Mul(c01, u1), hn::Mul(c11, t[1]));
  return hn::Add(hn::Mul(c0, u2), hn::Mul(c1, t[2]));
}

// cell_axis() of the three axes for a vector of points: the lower voxels i0, the upper ones i1 (clamped
// to N-1) and the upper ones' weights t. kPairs: the x axis's lower voxel is clamped to N-2 instead, so
// that the pair (i0, i0 + 1) loads as one element (see GridLookupVec); i1[0] is then not set.
template <bool kPairs, class DF>
HWY_INLINE void CellAxesVec(DF df, const hwy::HWY_NAMESPACE::Vec<DF>* u, const int32_t* n,
                            hwy::HWY_NAMESPACE::Vec<hwy::HWY_NAMESPACE::RebindToSigned<DF>>* i0,
                            hwy::HWY_NAMESPACE::Vec<hwy::HWY_NAMESPACE::RebindToSigned<DF>>* i1,
                            hwy::HWY_NAMESPACE::Vec<DF>* t) {
  namespace hn = hwy::HWY_NAMESPACE;
  const hn::RebindToSigned<DF> di;
  for (int d = 0; d < 3; ++d) {
    const auto q = CellAxisPos(df, u[d], n[d]);
    if (kPairs && d == 0) {
      i0[0] = hn::Min(hn::ConvertTo(di, hn::Floor(q)), hn::Set(di, n[0] - 2));
      t[0] = hn::Sub(q, hn::ConvertTo(df, i0[0]));
    } else {
      const auto fl = hn::Floor(q);
      i0[d] = hn::ConvertTo(di, fl);
      i1[d] = hn::Min(hn::Add(i0[d], hn::Set(di, 1)), hn::Set(di, n[d] - 1));
      t[d] = hn::Sub(q, fl);
    }
  }
}

// grid_lookup() for a vector of points. kPairs (volumes at least 2 voxels wide in x): each pair of
// x-neighbours loads as one 64-bit element (GatherPairs), half the gathered elements. The lower x
// corner is then clamped to N-2, so at q = N-1 the pair is (N-2, N-1) with weight 1 on the last
// voxel where the scalar code takes (N-1, N-1) with weight 0: v*0 + V*1 and V*1 + V*0 are both
// exactly V for finite values (up to the sign of a zero V), so the result still matches.
template <bool kPairs, class DF>
HWY_INLINE hwy::HWY_NAMESPACE::Vec<DF> GridLookupVec(DF df, const GridView& g, hwy::HWY_NAMESPACE::Vec<DF> ux,
                                                     hwy::HWY_NAMESPACE::Vec<DF> uy, hwy::HWY_NAMESPACE::Vec<DF> uz) {
  namespace hn = hwy::HWY_NAMESPACE;
  const hn::RebindToSigned<DF> di;
  using VI = hn::Vec<decltype(di)>;
  const auto sy = hn::Set(di, g.nx), sz = hn::Set(di, g.nx * g.ny);
  const hn::Vec<DF> u[3] = {ux, uy, uz};
  const int32_t dims[3] = {g.nx, g.ny, g.nz};
  VI i0[3], i1[3];
  hn::Vec<DF> t[3];
  CellAxesVec<kPairs>(df, u, dims, i0, i1, t);
  // The 8 corners v[x + 2y + 4z] (x = 0: i0, 1: i1), a row pair at a time.
  hn::Vec<DF> v[8];
  for (int k = 0; k < 4; ++k) {
    const VI row = hn::Add(hn::Mul(k & 1 ? i1[1] : i0[1], sy), hn::Mul(k & 2 ? i1[2] : i0[2], sz));
    if constexpr (kPairs) {
      GatherPairs(df, g.data, hn::Add(i0[0], row), &v[2 * k], &v[2 * k + 1]);
    } else {
      v[2 * k] = hn::GatherIndex(df, g.data, hn::Add(i0[0], row));
      v[2 * k + 1] = hn::GatherIndex(df, g.data, hn::Add(i1[0], row));
    }
  }
  return TrilinearCornersVec(df, v, t);
}

}  // namespace HWY_NAMESPACE
}  // namespace vnr
HWY_AFTER_NAMESPACE();

#endif  // per-target include guard
