// SIMD gathers shared by the per-target kernels (Highway's -inl.h convention: include it after
// <hwy/highway.h> inside a foreach_target translation unit).
#if defined(VNR_CORE_GATHER_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef VNR_CORE_GATHER_INL_H_
#undef VNR_CORE_GATHER_INL_H_
#else
#define VNR_CORE_GATHER_INL_H_
#endif

#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace vnr {
namespace HWY_NAMESPACE {

// base[idx[k]] into lane k of *a and base[idx[k] + 1] into lane k of *b, each pair gathered as one
// 64-bit element (at byte offset 4 * idx: pairs start at any float, not at 8-byte multiples).
// Gathers cost per element, so this halves their cost for neighbouring values.
template <class DF>
HWY_INLINE void GatherPairs(DF df, const float* base, hwy::HWY_NAMESPACE::Vec<hwy::HWY_NAMESPACE::RebindToSigned<DF>> idx,
                            hwy::HWY_NAMESPACE::Vec<DF>* a, hwy::HWY_NAMESPACE::Vec<DF>* b) {
  namespace hn = hwy::HWY_NAMESPACE;
#if HWY_TARGET == HWY_SCALAR
  *a = hn::GatherIndex(df, base, idx);
  *b = hn::GatherIndex(df, base + 1, idx);
#else
  const hn::Half<hn::RebindToSigned<DF>> dih;
  const hn::Repartition<int64_t, DF> di64;
  const hn::Repartition<uint64_t, DF> du64;
  const uint64_t* base64 = reinterpret_cast<const uint64_t*>(base);
  const auto lo = hn::BitCast(df, hn::GatherOffset(du64, base64, hn::ShiftLeft<2>(hn::PromoteTo(di64, hn::LowerHalf(dih, idx)))));
  const auto hi = hn::BitCast(df, hn::GatherOffset(du64, base64, hn::ShiftLeft<2>(hn::PromoteTo(di64, hn::UpperHalf(dih, idx)))));
  *a = hn::ConcatEven(df, hi, lo);
  *b = hn::ConcatOdd(df, hi, lo);
#endif
}

}  // namespace HWY_NAMESPACE
}  // namespace vnr
HWY_AFTER_NAMESPACE();

#endif  // per-target include guard
