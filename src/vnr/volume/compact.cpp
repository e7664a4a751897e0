#include <cmath>
#include <cstring>
#include <limits>
#include "vnr/core/parallel.h"
#include "vnr/volume/volume.h"

namespace vnr {
namespace {

template <typename T>
bool build(const Volume& v, big_vector<T>& store, std::vector<float>& lut) {
  const int64_t n = int64_t(v.data.size());
  const double span = v.hi - v.lo;
  const double tmin = dtype_min(v.source_dtype), tmax = dtype_max(v.source_dtype);
  const size_t levels = size_t(tmax - tmin) + 1;
  // The integer each normalised value came from (exact for unclamped voxels), then a table filled
  // from the data itself, verified to be consistent: any disagreement means "not representable".
  store.assign(size_t(n) + 4, 0);  // +4: 32-bit gathers read a few bytes past an element
  const int nt = num_threads();
  std::vector<std::vector<float>> luts(nt, std::vector<float>(levels, std::numeric_limits<float>::quiet_NaN()));
  std::vector<char> ok(nt, 1);
  parallel_threads([&](int t, int T_) {
    std::vector<float>& L = luts[t];
    const int64_t b = n * t / T_, e = n * (t + 1) / T_;
    for (int64_t i = b; i < e && ok[t]; ++i) {
      const float u = v.data[i];
      double r = std::nearbyint(double(u) * span + v.lo);
      r = r < tmin ? tmin : (r > tmax ? tmax : r);
      const size_t k = size_t(r - tmin);
      store[i] = T(int64_t(r));  // two's complement wrap maps int8/int16 into the unsigned store
      float& slot = L[k];
      if (std::isnan(slot)) slot = u;
      else if (std::memcmp(&slot, &u, 4) != 0) ok[t] = 0;
    }
  });
  lut.assign(levels, std::numeric_limits<float>::quiet_NaN());
  for (int t = 0; t < nt; ++t) {
    if (!ok[t]) return false;
    for (size_t k = 0; k < levels; ++k) {
      const float u = luts[t][k];
      if (std::isnan(u)) continue;
      if (std::isnan(lut[k])) lut[k] = u;
      else if (std::memcmp(&lut[k], &u, 4) != 0) return false;
    }
  }
  for (float& u : lut)
    if (std::isnan(u)) u = 0.0f;  // integers that never occur
  // Signed types are stored shifted into the unsigned range: index = value - min.
  if (tmin < 0) {
    const T shift = T(int64_t(-tmin));
    parallel_for_range(n, 1 << 20, [&](int64_t b, int64_t e) {
      for (int64_t i = b; i < e; ++i) store[i] = T(store[i] + shift);
    });
  }
  return true;
}

}  // namespace

bool make_compact_grid(const Volume& v, CompactGrid& out) {
  out = CompactGrid();
  const DType t = v.source_dtype;
  const bool is8 = t == DType::UInt8 || t == DType::Int8, is16 = t == DType::UInt16 || t == DType::Int16;
  if (!(is8 || is16) || v.data.empty() || v.hi == v.lo) return false;
  const bool ok = is8 ? build(v, out.u8, out.lut) : build(v, out.u16, out.lut);
  if (!ok) {
    out = CompactGrid();
    return false;
  }
  out.view = GridView{nullptr, int32_t(v.dims.x), int32_t(v.dims.y), int32_t(v.dims.z)};
  out.view.u8 = is8 ? out.u8.data() : nullptr;
  out.view.u16 = is16 ? out.u16.data() : nullptr;
  out.view.lut = out.lut.data();
  return true;
}

}  // namespace vnr
