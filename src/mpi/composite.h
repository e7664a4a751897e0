#pragma once
// Sort-last compositing, the pure part: visibility order of bricks, front-to-back "over" of
// premultiplied RGBA images, the row bands direct send gives each rank. No MPI here, so the
// single-process reference and the unit tests use exactly the functions the ranks run.
#include <cstddef>
#include <vector>
#include "vnr/math.h"
#include "vnr/image.h"

namespace vnr::mpi {

// An axis-aligned box [lo, hi) in any coordinates, the same as the eye's.
struct Bounds3f {
  Vec3f lo, hi;
};

// Front-to-back order (indices into boxes) of boxes that tile a rectilinear grid, seen from eye. Along
// each axis a ray moves monotonically away from the grid cell holding the eye (clamped to the grid),
// so a brick a ray meets first never has a larger sum of per-axis cell distances than one it meets
// later: sorting by that sum (ties by index) is a valid visibility order, for any eye.
std::vector<int> visibility_order(const std::vector<Bounds3f>& boxes, Vec3f eye);

// acc = acc over src, front to back, premultiplied: acc += (1 - acc.alpha) * src, per pixel.
void composite_behind(Vec4f* acc, const Vec4f* src, size_t n);

// The rows [y0, y1) of a height-row image that rank `rank` of `size` composites in direct send:
// contiguous bands, the first (height % size) one row taller.
struct RowBand {
  int y0 = 0, y1 = 0;
  int rows() const { return y1 - y0; }
};
RowBand row_band(int height, int rank, int size);

// The one-process reference: the images (all the same size) composited front to back in `order`.
Image composite_in_order(const std::vector<Image>& images, const std::vector<int>& order);

// A premultiplied image over an opaque background: rgb + (1 - alpha) * background, alpha 1.
void put_over_background(Image& img, Vec3f background);

}  // namespace vnr::mpi
