#pragma once
// Macro-cells (docs/semantics.md B.6, paper "Macro-Cell Optimization"): a coarse grid over the volume box whose
// cells carry the largest opacity the transfer function can give inside them. Ray marching skips
// transparent cells and adapts its step to the cell's opacity; the path tracer uses the values as
// per-cell majorants. `MacroCellView` + the DDA below are the per-ray (VNR_HD) part.
#include "vnr/render_options.h"
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>
#include "vnr/hd.h"
#include "vnr/math.h"
#include "vnr/core/value_range_grid.h"
#include "vnr/render/transfer_function.h"

namespace vnr {

struct MacroCellView {
  const float* max_opacity = nullptr;  // per cell, x fastest
  int32_t nx = 0, ny = 0, nz = 0;
  Vec3f cell_world{16, 16, 16};  // world size of one cell per axis
  Vec3f inv_cell_world{1.0f / 16, 1.0f / 16, 1.0f / 16};
};

// The nearest table entry of a normalised value (a table of n entries over [tf_lo, tf_lo + tf_w]).
VNR_HD VNR_INLINE int tf_nearest_entry(int n, float tf_lo, float tf_w, float u) {
  const float x = tf_w > 0 ? clampf((u - tf_lo) / tf_w, 0.0f, 1.0f) : 0.0f;
  return int(floorf(x * float(n - 1) + 0.5f));
}
// The largest opacity that transfer function gives to values in [lo, hi] (B.6: table entries
// floor(lo*(N-1)+0.5)-1 .. floor(hi*(N-1)+0.5)+1, clamped); 0 for an empty range (lo > hi).
// Single-source: MacroCells::update and the GPU's recompute.
VNR_HD VNR_INLINE float macrocell_max_opacity(const Vec4f* table, int n, float tf_lo, float tf_w, float lo, float hi) {
  if (lo > hi) return 0.0f;
  int a = tf_nearest_entry(n, tf_lo, tf_w, lo) - 1, b = tf_nearest_entry(n, tf_lo, tf_w, hi) + 1;
  a = a < 0 ? 0 : a;
  b = b > n - 1 ? n - 1 : b;
  float m = 0;
  for (int i = a; i <= b; ++i) m = m < table[i].w ? table[i].w : m;
  return m;
}

class MacroCells {
public:
  // `ranges` = per-cell value ranges; `box` = world size of the volume box (dims * spacing).
  MacroCells(ValueRangeGrid ranges, Vec3f box);
  // One cell over the whole box (--macrocells off): its range is [lo, hi] (the full range by default).
  static MacroCells single(Int3 dims, Vec3f box, float lo = 0, float hi = 1);
  // Recomputes the per-cell max opacity for a transfer function (B.6: table entries
  // floor(min*(N-1)+0.5)-1 .. floor(max*(N-1)+0.5)+1, clamped, over the TF's window).
  void update(const TransferFunction& tf);
  MacroCellView view() const;
  const ValueRangeGrid& ranges() const { return ranges_; }
  const std::vector<float>& max_opacity() const { return max_opacity_; }
  // Fraction of cells that are transparent for the current TF (for reports).
  double empty_fraction() const;

private:
  ValueRangeGrid ranges_;
  Vec3f box_, cell_world_;
  std::vector<float> max_opacity_;
};

// 3-D DDA (Amanatides-Woo) over the macro-cells, resumable: the whole traversal state lives in this
// POD so a streaming ray can stop after any cell and continue in the next iteration.
struct DdaState {
  int32_t cell[3];
  int32_t step[3];
  float t_next[3];   // ray parameter where the ray leaves the current cell along each axis
  float t_delta[3];  // ray parameter per cell along each axis
  float t_end;       // where the ray leaves the volume box
};

VNR_HD VNR_INLINE void dda_init(const MacroCellView& mc, Vec3f org, Vec3f dir, float t0, float t1, DdaState& s) {
  const float o[3] = {org.x, org.y, org.z}, d[3] = {dir.x, dir.y, dir.z};
  const float cw[3] = {mc.cell_world.x, mc.cell_world.y, mc.cell_world.z};
  const float icw[3] = {mc.inv_cell_world.x, mc.inv_cell_world.y, mc.inv_cell_world.z};
  const int32_t n[3] = {mc.nx, mc.ny, mc.nz};
  for (int a = 0; a < 3; ++a) {
    float p = o[a] + d[a] * t0;
    int32_t c = int32_t(floorf(p * icw[a]));
    c = c < 0 ? 0 : (c > n[a] - 1 ? n[a] - 1 : c);
    s.cell[a] = c;
    if (d[a] > 0) {
      s.step[a] = 1;
      s.t_delta[a] = cw[a] / d[a];
      s.t_next[a] = (float(c + 1) * cw[a] - o[a]) / d[a];
    } else if (d[a] < 0) {
      s.step[a] = -1;
      s.t_delta[a] = -cw[a] / d[a];
      s.t_next[a] = (float(c) * cw[a] - o[a]) / d[a];
    } else {
      s.step[a] = 0;
      s.t_delta[a] = INFINITY;
      s.t_next[a] = INFINITY;
    }
  }
  s.t_end = t1;
}

VNR_HD VNR_INLINE int64_t dda_cell_index(const MacroCellView& mc, const DdaState& s) {
  return s.cell[0] + int64_t(mc.nx) * (s.cell[1] + int64_t(mc.ny) * s.cell[2]);
}

// Where the ray leaves the current cell (never beyond the box exit).
VNR_HD VNR_INLINE float dda_cell_exit(const DdaState& s) {
  float t = s.t_next[0] < s.t_next[1] ? s.t_next[0] : s.t_next[1];
  t = t < s.t_next[2] ? t : s.t_next[2];
  return t < s.t_end ? t : s.t_end;
}

// Steps into the next cell; returns false when the ray has left the grid or the box. The axis is picked
// by branches rather than an array index: a GPU thread then keeps the whole state in registers.
VNR_HD VNR_INLINE bool dda_step_axis(int32_t& cell, int32_t step, float& t_next, float t_delta, float t_end,
                                     int32_t n) {
  if (t_next >= t_end) return false;
  cell += step;
  if (cell < 0 || cell >= n) return false;
  t_next += t_delta;
  return true;
}
VNR_HD VNR_INLINE bool dda_advance(const MacroCellView& mc, DdaState& s) {
  const float t0 = s.t_next[0], t1 = s.t_next[1], t2 = s.t_next[2];
  if (t0 < t1 && t0 < t2) return dda_step_axis(s.cell[0], s.step[0], s.t_next[0], s.t_delta[0], s.t_end, mc.nx);
  if (!(t0 < t1) && t1 < t2) return dda_step_axis(s.cell[1], s.step[1], s.t_next[1], s.t_delta[1], s.t_end, mc.ny);
  return dda_step_axis(s.cell[2], s.step[2], s.t_next[2], s.t_delta[2], s.t_end, mc.nz);
}

// Ray / axis-aligned box [0, box] intersection; false when the ray misses it.
VNR_HD VNR_INLINE bool intersect_box(Vec3f org, Vec3f dir, Vec3f box, float* t0, float* t1) {
  const float o[3] = {org.x, org.y, org.z}, d[3] = {dir.x, dir.y, dir.z}, b[3] = {box.x, box.y, box.z};
  float lo = 0, hi = INFINITY;
  for (int a = 0; a < 3; ++a) {
    if (d[a] == 0) {
      if (o[a] < 0 || o[a] > b[a]) return false;
      continue;
    }
    float inv = 1.0f / d[a];
    float ta = (0 - o[a]) * inv, tb = (b[a] - o[a]) * inv;
    if (ta > tb) {
      float t = ta;
      ta = tb;
      tb = t;
    }
    lo = ta > lo ? ta : lo;
    hi = tb < hi ? tb : hi;
  }
  *t0 = lo;
  *t1 = hi;
  return lo < hi;
}

}  // namespace vnr
