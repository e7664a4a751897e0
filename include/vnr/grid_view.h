#pragma once
// The POD view of a normalised grid and its cell-centred trilinear lookup: what per-sample code of
// every layer reads (training targets, ground-truth rendering on the CPU and the GPU, value ranges).
#include <cstdint>
#include "vnr/hd.h"

namespace vnr {

// A normalised grid, x fastest (volume/volume.h's view_of gives one of a loaded Volume).
struct GridView {
  const float* data = nullptr;
  int32_t nx = 0, ny = 0, nz = 0;
};

// Cell-centred, clamp-to-edge trilinear interpolation at u in [0,1)^3 (docs/semantics.md B.2) over any
// voxel accessor at(x, y, z) with global indices: p = u*N - 0.5 clamped to [0, N-1] per axis;
// trilinear between floor(p) and min(floor(p)+1, N-1). The in-memory grid, out-of-core blocks and
// memory-mapped files all go through this one function, so they agree bit for bit.
// One axis of it: the two voxel indices and the weight of the upper one.
struct CellAxis {
  int32_t i0, i1;
  float t;
};
VNR_HD VNR_INLINE CellAxis cell_axis(float u, int32_t n) {
  const float p = u * float(n) - 0.5f, hi = float(n - 1);
  const float q = !(p >= 0.f) ? 0.f : (p > hi ? hi : p);  // NaN -> 0
  const int32_t i0 = int32_t(q);  // q >= 0: truncation is floor, and far cheaper than floorf without SSE4.1
  return CellAxis{i0, i0 + 1 < n ? i0 + 1 : n - 1, q - float(i0)};
}
// Written out per axis (no arrays) so the compiler keeps everything in registers: the lookup is the
// innermost work of grid rendering (about half the instructions of a grid ray-marching sample).
// The interpolation itself, over the 8 corner values v[x + 2y + 4z] (x = 0: i0, 1: i1).
VNR_HD VNR_INLINE float trilinear_corners(const CellAxis& x, const CellAxis& y, const CellAxis& z, const float* v) {
  float c00 = v[0] * (1 - x.t) + v[1] * x.t;
  float c10 = v[2] * (1 - x.t) + v[3] * x.t;
  float c01 = v[4] * (1 - x.t) + v[5] * x.t;
  float c11 = v[6] * (1 - x.t) + v[7] * x.t;
  float c0 = c00 * (1 - y.t) + c10 * y.t;
  float c1 = c01 * (1 - y.t) + c11 * y.t;
  return c0 * (1 - z.t) + c1 * z.t;
}
template <typename At>
VNR_HD VNR_INLINE float cell_centred_trilinear(int32_t nx, int32_t ny, int32_t nz, float ux, float uy, float uz,
                                               const At& at) {
  const CellAxis x = cell_axis(ux, nx), y = cell_axis(uy, ny), z = cell_axis(uz, nz);
  const float v[8] = {at(x.i0, y.i0, z.i0), at(x.i1, y.i0, z.i0), at(x.i0, y.i1, z.i0), at(x.i1, y.i1, z.i0),
                      at(x.i0, y.i0, z.i1), at(x.i1, y.i0, z.i1), at(x.i0, y.i1, z.i1), at(x.i1, y.i1, z.i1)};
  return trilinear_corners(x, y, z, v);
}

// The lookup on an in-memory normalised grid.
// Same arithmetic as cell_centred_trilinear; the corners are addressed from one base offset (a
// third fewer instructions per grid-rendering sample than eight independent index computations).
VNR_HD VNR_INLINE float grid_lookup(const GridView& g, float ux, float uy, float uz) {
  const CellAxis x = cell_axis(ux, g.nx), y = cell_axis(uy, g.ny), z = cell_axis(uz, g.nz);
  const int64_t sy = g.nx, sz = int64_t(g.nx) * g.ny;
  const float* b = g.data + (x.i0 + y.i0 * sy + z.i0 * sz);
  const int64_t dx = x.i1 - x.i0, dy = (y.i1 - y.i0) * sy, dz = (z.i1 - z.i0) * sz;
  const float v[8] = {b[0], b[dx], b[dy], b[dx + dy], b[dz], b[dx + dz], b[dy + dz], b[dx + dy + dz]};
  return trilinear_corners(x, y, z, v);
}

// The SIMD versions of the lookup (grid_lookup_batch, the grid's ray packets) gather with 32-bit
// indices: volumes below 2^31 voxels.
inline bool grid_fits_gather_indices(const GridView& g) {
  return uint64_t(g.nx) * uint64_t(g.ny) * uint64_t(g.nz) < (uint64_t(1) << 31);
}

}  // namespace vnr
