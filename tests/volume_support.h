// Helpers shared by the volume tests (test_volume*.cpp): values that exercise each dtype's range,
// the normalisation check, raw-reader options and the small non-cubic grid they use.
#pragma once

#include <gtest/gtest.h>
#include <algorithm>
#include <string>
#include <vector>
#include "vnr/dtype.h"
#include "vnr/volume/volume.h"

namespace vnr::test {

// Values exercising each type's range (signed types go negative; wide types sit far from zero
// with a narrow spread, which float storage must not wash out).
inline std::vector<double> test_values(DType t, size_t n) {
  std::vector<double> v(n);
  for (size_t i = 0; i < n; ++i) {
    int64_t k = int64_t(i);
    switch (t) {
      case DType::Int8: v[i] = double(-100 + (k * 7) % 200); break;
      case DType::UInt8: v[i] = double((k * 7) % 256); break;
      case DType::Int16: v[i] = double(-30000 + (k * 311) % 60000); break;
      case DType::UInt16: v[i] = double((k * 977) % 65536); break;
      case DType::Int32: v[i] = double(-2000000000LL + (k * 123456789LL) % 4000000000LL); break;
      case DType::UInt32: v[i] = double(4000000000LL + k * 3); break;
      case DType::Float32: v[i] = double(float(k * 0.37 - 10.0)); break;
      case DType::Float64: v[i] = 1e12 + double(k) * 0.001; break;
    }
  }
  return v;
}

inline void expect_normalised(const Volume& vol, const std::vector<double>& values, double tol = 1e-6) {
  ASSERT_EQ(vol.data.size(), values.size());
  double lo = *std::min_element(values.begin(), values.end());
  double hi = *std::max_element(values.begin(), values.end());
  EXPECT_DOUBLE_EQ(vol.lo, lo);
  EXPECT_DOUBLE_EQ(vol.hi, hi);
  for (size_t i = 0; i < values.size(); ++i)
    ASSERT_NEAR(vol.data[i], (values[i] - lo) / (hi - lo), tol) << "voxel " << i;
}

inline RawOptions raw_opts(Int3 dims, const std::string& dtype) {
  RawOptions o;
  o.dims = dims;
  o.dtype = dtype;
  return o;
}

inline const Int3 kDims{5, 7, 3};  // non-cubic on purpose: catches swapped axes

}  // namespace vnr::test
