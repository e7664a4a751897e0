// vnr.metrics: `vnr eval`'s PSNR and 3-D SSIM (vnr/metrics.h) over numpy arrays in original units.
#include "bindings.h"
#include "vnr/error.h"
#include "vnr/metrics.h"

namespace vnr::py {

namespace {

// The reference normalised as `vnr eval` normalises the volume (load_volume: value range, clamped),
// the test mapped with the same range but not clamped, as a model's output is compared.
struct NormalisedPair {
  Volume reference;
  std::vector<float> test;
};

NormalisedPair normalise_pair(const pyb::array& a, const pyb::array& b, std::optional<std::pair<double, double>> range) {
  if (a.ndim() != 3 || b.ndim() != 3) fail("metrics compare two 3-D arrays (nz, ny, nx)");
  for (int i = 0; i < 3; ++i)
    if (a.shape(i) != b.shape(i))
      fail("the arrays differ in shape: ({}, {}, {}) and ({}, {}, {})", a.shape(0), a.shape(1), a.shape(2), b.shape(0),
           b.shape(1), b.shape(2));
  if (!(a.flags() & pyb::array::c_style) || !(b.flags() & pyb::array::c_style))
    fail("metrics need C-ordered arrays (vnr.metrics makes them so)");
  NormalisedPair p;
  std::optional<double> lo, hi;
  if (range) std::tie(lo, hi) = *range;
  p.reference = volume_from_numpy(a, lo, hi);
  pyb::array_t<double> bd = pyb::array_t<double, pyb::array::c_style | pyb::array::forcecast>::ensure(b);
  if (!bd) fail("the second array is not numeric");
  const double* src = bd.data();
  const size_t n = size_t(bd.size());
  p.test.resize(n);
  const double l = p.reference.lo, w = p.reference.hi - p.reference.lo;
  pyb::gil_scoped_release release;
  for (size_t i = 0; i < n; ++i) {
    if (!std::isfinite(src[i])) fail("the second array has a non-finite value at index {}", i);
    p.test[i] = w > 0 ? float((src[i] - l) / w) : 0.f;
  }
  return p;
}

}  // namespace

void bind_metrics(pyb::module_& m) {
  m.def(
      "_error_stats",
      [](const pyb::array& a, const pyb::array& b, std::optional<std::pair<double, double>> range) {
        NormalisedPair p = normalise_pair(a, b, range);
        ErrorStats e;
        {
          pyb::gil_scoped_release release;
          e = error_stats(p.reference.data.data(), p.test.data(), p.reference.dims);
        }
        return std::make_tuple(e.psnr, e.mse, e.max_abs_error);
      },
      pyb::arg("reference"), pyb::arg("test"), pyb::arg("value_range"), "vnr.metrics.psnr's computation.");
  m.def(
      "_ssim",
      [](const pyb::array& a, const pyb::array& b, std::optional<std::pair<double, double>> range) {
        NormalisedPair p = normalise_pair(a, b, range);
        pyb::gil_scoped_release release;
        return ssim3d(p.reference.data.data(), p.test.data(), p.reference.dims);
      },
      pyb::arg("reference"), pyb::arg("test"), pyb::arg("value_range"), "vnr.metrics.ssim's computation.");
}

}  // namespace vnr::py
