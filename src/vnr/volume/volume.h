#pragma once
// The volume layer's own helpers; the types (Volume, VolumeDesc, RawOptions, LoadOptions, view_of) are
// the public vnr/volume.h's.
#include <cstdint>
#include "vnr/grid_view.h"
#include "vnr/hd.h"
#include "vnr/math.h"
#include "vnr/volume.h"

namespace vnr {

// Normalised coordinates of the centre of voxel v (x + dims.x * (y + dims.y * z)): (i + 0.5) / n per
// axis, the one expression every decoder (CPU, GPU, whole slices or chosen voxels) uses.
VNR_HD VNR_INLINE void voxel_centre(Int3 dims, int64_t v, float* x, float* y, float* z) {
  const int64_t ix = v % dims.x, iy = (v / dims.x) % dims.y, iz = v / (dims.x * dims.y);
  *x = (float(ix) + 0.5f) / float(dims.x);
  *y = (float(iy) + 0.5f) / float(dims.y);
  *z = (float(iz) + 0.5f) / float(dims.z);
}

// grid_lookup (vnr/grid_view.h) for n points (SoA), vectorised with gathers; bit-identical to it.
void grid_lookup_batch(const GridView& g, const float* x, const float* y, const float* z, int64_t n, float* out);

}  // namespace vnr
