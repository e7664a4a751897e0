#pragma once
// Per-macro-cell value ranges (compat.md B.6): cells of `cell_size` voxels per axis
// (ceil(N / cell_size) cells per axis), each with the [min, max] of the normalised values that can be
// interpolated inside it. A value known at world position q (voxel units; voxel i's centre is at
// i + 0.5) reaches every point within one voxel of q through trilinear interpolation, so it widens
// every cell that overlaps [q - 1, q + 1] per axis. Cells never touched stay empty (min > max).
#include <cstdint>
#include <vector>
#include "vnr/core/math.h"
#include "vnr/volume/volume.h"

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

// Every voxel of a normalised grid (the precomputed construction). Parallel.
ValueRangeGrid value_ranges_from_grid(const GridView& g, int cell_size = 16);

}  // namespace vnr
