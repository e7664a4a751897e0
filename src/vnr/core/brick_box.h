#pragma once
// Boxes of voxels and the blend weight of a brick of a multi-brick model (docs/MODEL_FORMAT.md,
// "Multi-brick models"): per-sample, single-source code shared by decoding (train) and rendering (fields).
#include <algorithm>
#include <cstdint>
#include <vector>
#include "vnr/hd.h"
#include "vnr/math.h"

namespace vnr {

// Voxels [lo, hi) per axis.

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
// each axis: continuous, so the normalised blend of neighbouring bricks is continuous across a face,
// and a brick's least accurate voxels (its ghost edge) count for nothing. 0 outside the trained box.
VNR_HD inline float brick_blend_ramp(float p, float lo, float hi, float tlo, float thi) {
  if (p < lo) return p > tlo ? (p - tlo) / (lo - tlo) : 0.f;  // p > tlo implies tlo < lo
  if (p > hi) return p < thi ? (thi - p) / (thi - hi) : 0.f;
  return 1.f;
}
VNR_HD inline float brick_blend_weight(const Box3& owned, const Box3& trained, float px, float py, float pz) {
  return brick_blend_ramp(px, float(owned.lo.x), float(owned.hi.x), float(trained.lo.x), float(trained.hi.x)) *
         brick_blend_ramp(py, float(owned.lo.y), float(owned.hi.y), float(trained.lo.y), float(trained.hi.y)) *
         brick_blend_ramp(pz, float(owned.lo.z), float(owned.hi.z), float(trained.lo.z), float(trained.hi.z));
}

// The bricks' boxes on their grid (x fastest), as the blended evaluation needs them.
struct BrickLayout {
  Int3 dims;           // the whole volume
  Int3 grid{1, 1, 1};  // bricks per axis
  std::vector<Box3> owned, trained;

  // Grid coordinate along `axis` of the brick owning position p (voxel units, clamped to the volume).
  int owned_coord(int axis, float p) const {
    const int64_t stride = axis == 0 ? 1 : (axis == 1 ? grid.x : grid.x * grid.y);
    int lo = 0, hi = int(grid[axis]) - 1;
    while (lo < hi) {  // the last brick whose owned.lo <= p
      const int mid = (lo + hi + 1) / 2;
      if (float(owned[size_t(mid * stride)].lo[axis]) <= p) lo = mid;
      else hi = mid - 1;
    }
    return lo;
  }
  // Calls fn(brick, weight, local x, y, z) for every brick with a positive weight at the normalised
  // point u (local: the brick network's normalised coordinates over its trained box). A brick is wider
  // than the ghost layer, so only the owning brick and its 26 neighbours can reach a point.
  template <class Fn>
  void for_each_brick_at(float ux, float uy, float uz, Fn&& fn) const {
    const float u[3] = {ux, uy, uz};
    float p[3];
    int c[3];
    for (int a = 0; a < 3; ++a) {
      p[a] = std::clamp(u[a] * float(dims[a]), 0.f, float(dims[a]));
      c[a] = owned_coord(a, p[a]);
    }
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int64_t bx = c[0] + dx, by = c[1] + dy, bz = c[2] + dz;
          if (bx < 0 || by < 0 || bz < 0 || bx >= grid.x || by >= grid.y || bz >= grid.z) continue;
          const int b = int(bx + grid.x * (by + grid.y * bz));
          const Box3& t = trained[size_t(b)];
          const float w = brick_blend_weight(owned[size_t(b)], t, p[0], p[1], p[2]);
          if (w > 0)
            fn(b, w, (p[0] - float(t.lo.x)) / float(t.hi.x - t.lo.x), (p[1] - float(t.lo.y)) / float(t.hi.y - t.lo.y),
               (p[2] - float(t.lo.z)) / float(t.hi.z - t.lo.z));
        }
  }
  // One blended value: sum of w * eval(brick, local xyz) / sum of w (every point has its owning brick).
  template <class Eval>
  float blend_point(float ux, float uy, float uz, Eval&& eval) const {
    float num = 0, den = 0;
    for_each_brick_at(ux, uy, uz, [&](int b, float w, float lx, float ly, float lz) {
      num += w * eval(b, lx, ly, lz);
      den += w;
    });
    return den > 0 ? num / den : 0.f;
  }
  // n blended values at points (x[i], y[i], z[i]): the points of each brick are gathered and handed to
  // infer(brick, local xyz interleaved, m, values) in one batch, so batched networks stay batched.
  template <class Coords, class Infer>
  void blend_batch(int64_t n, Coords&& coords, float* out, Infer&& infer) const {
    struct Item {
      int64_t point;
      float w, x, y, z;
    };
    std::vector<std::vector<Item>> per_brick(owned.size());
    for (int64_t i = 0; i < n; ++i) {
      float x, y, z;
      coords(i, &x, &y, &z);
      for_each_brick_at(x, y, z, [&](int b, float w, float lx, float ly, float lz) {
        per_brick[size_t(b)].push_back({i, w, lx, ly, lz});
      });
    }
    std::vector<float> den(size_t(n), 0.f), local, vals;
    std::fill(out, out + n, 0.f);
    for (size_t b = 0; b < per_brick.size(); ++b) {
      const std::vector<Item>& list = per_brick[b];
      if (list.empty()) continue;
      local.resize(list.size() * 3);
      vals.resize(list.size());
      for (size_t k = 0; k < list.size(); ++k) {
        local[3 * k] = list[k].x;
        local[3 * k + 1] = list[k].y;
        local[3 * k + 2] = list[k].z;
      }
      infer(int(b), local.data(), int64_t(list.size()), vals.data());
      for (size_t k = 0; k < list.size(); ++k) {
        out[list[k].point] += list[k].w * vals[k];
        den[size_t(list[k].point)] += list[k].w;
      }
    }
    for (int64_t i = 0; i < n; ++i) out[i] = den[size_t(i)] > 0 ? out[i] / den[size_t(i)] : 0.f;
  }
};

}  // namespace vnr
