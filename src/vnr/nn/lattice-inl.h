// grid_corners()'s per-axis lattice position for a vector of points, shared by the per-target grid
// kernels (Highway's -inl.h convention: include it after <hwy/highway.h> inside a foreach_target
// translation unit). Exactly the scalar operations, so the SIMD encodings stay bit-identical to it.
#if defined(VNR_NN_LATTICE_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef VNR_NN_LATTICE_INL_H_
#undef VNR_NN_LATTICE_INL_H_
#else
#define VNR_NN_LATTICE_INL_H_
#endif

#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace vnr {
namespace HWY_NAMESPACE {

// p = fma(scale, x, 0.5): *cell = floor(p), *t = p - floor(p) (smoothstepped when smooth) — the
// weight of the upper corner — and *t_lower = 1 - *t.
template <class DF>
HWY_INLINE void LatticeAxis(DF df, hwy::HWY_NAMESPACE::Vec<DF> scale, hwy::HWY_NAMESPACE::Vec<DF> x, bool smooth,
                            hwy::HWY_NAMESPACE::Vec<hwy::HWY_NAMESPACE::RebindToUnsigned<DF>>* cell,
                            hwy::HWY_NAMESPACE::Vec<DF>* t, hwy::HWY_NAMESPACE::Vec<DF>* t_lower) {
  namespace hn = hwy::HWY_NAMESPACE;
  const auto p = hn::MulAdd(scale, x, hn::Set(df, 0.5f));
  const auto fl = hn::Floor(p);
  *cell = hn::BitCast(hn::RebindToUnsigned<DF>(), hn::ConvertTo(hn::RebindToSigned<DF>(), fl));
  auto u = hn::Sub(p, fl);
  if (smooth) u = hn::Mul(hn::Mul(u, u), hn::Sub(hn::Set(df, 3.0f), hn::Mul(hn::Set(df, 2.0f), u)));
  *t = u;
  *t_lower = hn::Sub(hn::Set(df, 1.0f), u);
}

}  // namespace HWY_NAMESPACE
}  // namespace vnr
HWY_AFTER_NAMESPACE();

#endif  // per-target include guard
