#pragma once
// Per-macro-cell value ranges (docs/semantics.md B.6): cells of `cell_size` voxels per axis
// (ceil(N / cell_size) cells per axis), each with the [min, max] of the normalised values that can be
// interpolated inside it. A value known at world position q (voxel units; voxel i's centre is at
// i + 0.5) reaches every point within one voxel of q through trilinear interpolation, so it widens
// every cell that overlaps [q - 1, q + 1] per axis. Cells never touched stay empty (min > max).
#include <cmath>
#include <cstdint>
#include <vector>
#include "vnr/grid_view.h"
#include "vnr/hd.h"
#include "vnr/math.h"

namespace vnr {

struct ValueRangeGrid {
  Int3 volume_dims;        // voxels the grid covers
  int cell_size = 16;      // voxels per cell per axis
  Int3 cells;              // cells per axis
  std::vector<float> lo, hi;  // per cell, x fastest; empty cell: lo = +inf, hi = -inf

  ValueRangeGrid() = default;
  ValueRangeGrid(Int3 dims, int cell_size);
  int64_t count() const { return int64_t(cells.count()); }
  bool empty(int64_t c) const { return lo[c] > hi[c]; }
  void clear();
  // Widens the cells around world position (px, py, pz) (voxel units) by value v.
  void add(float px, float py, float pz, float v);
  // n samples at normalised coordinates u in [0,1)^3 (SoA) with values v: the online construction
  // from training batches (world position = u * N).
  void add_samples(const float* ux, const float* uy, const float* uz, const float* v, int64_t n);
  void merge(const ValueRangeGrid& other);
  // (min, max) per cell as the model files store them (docs/MODEL_FORMAT.md); an empty cell is (1, -1),
  // which is what instantvnr's (0, 0) decodes to.
  std::vector<float> to_pairs() const;
  static ValueRangeGrid from_pairs(Int3 dims, Int3 cells, const std::vector<float>& pairs);
};

// Per-sample / per-cell pieces, single-source for the CPU and the GPU (online ranges of training batches,
// ranges of a grid).

// The cells [*c0, *c1] along one axis that a value known at world position p (voxel units) widens.
VNR_HD VNR_INLINE void value_range_cells(float p, float inv_cell_size, int32_t n_cells, int32_t* c0, int32_t* c1) {
  int32_t a = int32_t(floorf((p - 1.0f) * inv_cell_size)), b = int32_t(floorf((p + 1.0f) * inv_cell_size));
  *c0 = a < 0 ? 0 : (a > n_cells - 1 ? n_cells - 1 : a);
  *c1 = b < 0 ? 0 : (b > n_cells - 1 ? n_cells - 1 : b);
}

// [min, max] of the voxels that reach cell (cx, cy, cz) of size cs: a voxel at centre q reaches
// [q - 1, q + 1], so the cell gets voxels [c*cs - 1, (c+1)*cs] per axis (clamped to the grid).
VNR_HD VNR_INLINE void cell_value_range(const GridView& g, int32_t cs, int32_t cx, int32_t cy, int32_t cz, float* lo,
                                        float* hi) {
  const int32_t n[3] = {g.nx, g.ny, g.nz}, ci[3] = {cx, cy, cz};
  int32_t b[3], e[3];
  for (int a = 0; a < 3; ++a) {
    // voxel i (centre i + 0.5) overlaps cell [c*cs, (c+1)*cs] when i + 1.5 >= c*cs and i - 0.5 <= (c+1)*cs
    b[a] = ci[a] * cs - 1 > 0 ? ci[a] * cs - 1 : 0;
    e[a] = (ci[a] + 1) * cs < n[a] - 1 ? (ci[a] + 1) * cs : n[a] - 1;
  }
  float l = INFINITY, h = -INFINITY;
  for (int32_t z = b[2]; z <= e[2]; ++z)
    for (int32_t y = b[1]; y <= e[1]; ++y) {
      const float* row = g.data + (int64_t(z) * n[1] + y) * n[0];
      for (int32_t x = b[0]; x <= e[0]; ++x) {
        const float v = row[x];
        l = v < l ? v : l;
        h = h < v ? v : h;
      }
    }
  *lo = l;
  *hi = h;
}

// Every voxel of a normalised grid (the precomputed construction). Parallel.
ValueRangeGrid value_ranges_from_grid(const GridView& g, int cell_size = 16);

}  // namespace vnr
