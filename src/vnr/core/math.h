#pragma once
#include <cmath>
#include <cstdint>
#include "vnr/core/hd.h"

namespace vnr {

// Volume dimensions (x fastest in memory).
struct Int3 {
  int64_t x = 0, y = 0, z = 0;
  VNR_HD int64_t& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
  VNR_HD int64_t operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
  VNR_HD uint64_t count() const { return uint64_t(x) * uint64_t(y) * uint64_t(z); }
  friend bool operator==(const Int3&, const Int3&) = default;
};

struct Vec3f {
  float x = 0, y = 0, z = 0;
  VNR_HD float operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
};

VNR_HD inline float clampf(float v, float lo, float hi) { return v < lo ? lo : (v > hi ? hi : v); }

inline uint64_t next_multiple(uint64_t v, uint64_t m) { return (v + m - 1) / m * m; }

}  // namespace vnr
