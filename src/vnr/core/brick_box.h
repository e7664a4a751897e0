#pragma once
// Boxes of voxels and the blend weight of a brick of a multi-brick model (docs/MODEL_FORMAT.md,
// "Multi-brick models"): per-sample, single-source code shared by decoding (train) and rendering (fields).
#include <cstdint>
#include "vnr/core/hd.h"
#include "vnr/core/math.h"

namespace vnr {

// Voxels [lo, hi) per axis.
struct Box3 {
  Int3 lo, hi;
  VNR_HD Int3 size() const { return Int3{hi.x - lo.x, hi.y - lo.y, hi.z - lo.z}; }
  VNR_HD uint64_t voxels() const { return size().count(); }
  VNR_HD bool empty() const { return hi.x <= lo.x || hi.y <= lo.y || hi.z <= lo.z; }
  friend bool operator==(const Box3&, const Box3&) = default;
};

inline Box3 intersect(const Box3& a, const Box3& b) {
  Box3 r;
  for (int i = 0; i < 3; ++i) {
    r.lo[i] = a.lo[i] > b.lo[i] ? a.lo[i] : b.lo[i];
    r.hi[i] = a.hi[i] < b.hi[i] ? a.hi[i] : b.hi[i];
    if (r.hi[i] < r.lo[i]) r.hi[i] = r.lo[i];
  }
  return r;
}

// A brick's weight at position p (in voxel units of the whole volume: voxel i spans [i, i + 1)):
// 1 inside its owned box, falling linearly to 0 at the edge of its trained box (owned + ghost) on
// each axis, so the weights of neighbouring bricks sum to 1 across a face and a brick's least
// accurate voxels (its ghost edge) count for nothing. 0 outside the trained box.
VNR_HD inline float brick_blend_ramp(float p, float lo, float hi, float tlo, float thi) {
  if (p < lo && tlo < lo) return p <= tlo ? 0.f : (p - tlo) / (lo - tlo);  // no ghost (volume edge): 1
  if (p > hi && thi > hi) return p >= thi ? 0.f : (thi - p) / (thi - hi);
  return 1.f;
}
VNR_HD inline float brick_blend_weight(const Box3& owned, const Box3& trained, float px, float py, float pz) {
  return brick_blend_ramp(px, float(owned.lo.x), float(owned.hi.x), float(trained.lo.x), float(trained.hi.x)) *
         brick_blend_ramp(py, float(owned.lo.y), float(owned.hi.y), float(trained.lo.y), float(trained.hi.y)) *
         brick_blend_ramp(pz, float(owned.lo.z), float(owned.hi.z), float(trained.lo.z), float(trained.hi.z));
}

}  // namespace vnr
