#include "mpi/composite.h"
#include <algorithm>
#include <cstdlib>
#include "vnr/error.h"

namespace vnr::mpi {

namespace {
// The grid cell along one axis of each box (its rank among the distinct lower faces) and of the eye.
struct AxisCells {
  std::vector<int> of_box;
  int of_eye = 0;
};
AxisCells axis_cells(const std::vector<Bounds3f>& boxes, float Vec3f::*axis, float eye) {
  std::vector<float> faces;
  for (const Bounds3f& b : boxes) faces.push_back(b.lo.*axis);
  std::sort(faces.begin(), faces.end());
  faces.erase(std::unique(faces.begin(), faces.end()), faces.end());
  AxisCells c;
  for (const Bounds3f& b : boxes)
    c.of_box.push_back(int(std::lower_bound(faces.begin(), faces.end(), b.lo.*axis) - faces.begin()));
  // The last face at or below the eye; an eye below every face counts as in the first cell.
  c.of_eye = std::max(0, int(std::upper_bound(faces.begin(), faces.end(), eye) - faces.begin()) - 1);
  return c;
}
}  // namespace

std::vector<int> visibility_order(const std::vector<Bounds3f>& boxes, Vec3f eye) {
  const AxisCells cx = axis_cells(boxes, &Vec3f::x, eye.x);
  const AxisCells cy = axis_cells(boxes, &Vec3f::y, eye.y);
  const AxisCells cz = axis_cells(boxes, &Vec3f::z, eye.z);
  std::vector<int> distance(boxes.size()), order(boxes.size());
  for (size_t i = 0; i < boxes.size(); ++i) {
    distance[i] = std::abs(cx.of_box[i] - cx.of_eye) + std::abs(cy.of_box[i] - cy.of_eye) +
                  std::abs(cz.of_box[i] - cz.of_eye);
    order[i] = int(i);
  }
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return distance[a] < distance[b]; });
  return order;
}

void composite_behind(Vec4f* acc, const Vec4f* src, size_t n) {
  for (size_t i = 0; i < n; ++i) {
    const float t = 1.0f - acc[i].w;
    acc[i].x += t * src[i].x;
    acc[i].y += t * src[i].y;
    acc[i].z += t * src[i].z;
    acc[i].w += t * src[i].w;
  }
}

RowBand row_band(int height, int rank, int size) {
  if (size <= 0 || rank < 0 || rank >= size || height < 0) fail("row_band: rank {} of {} is not a rank", rank, size);
  const int base = height / size, extra = height % size;
  RowBand b;
  b.y0 = rank * base + std::min(rank, extra);
  b.y1 = b.y0 + base + (rank < extra ? 1 : 0);
  return b;
}

Image composite_in_order(const std::vector<Image>& images, const std::vector<int>& order) {
  if (images.empty()) fail("composite_in_order: no images");
  Image out(images[0].width, images[0].height);
  for (int i : order) {
    const Image& img = images.at(size_t(i));
    if (img.width != out.width || img.height != out.height)
      fail("composite_in_order: image {} is {}x{}, not {}x{}", i, img.width, img.height, out.width, out.height);
    composite_behind(out.pixels.data(), img.pixels.data(), out.pixels.size());
  }
  return out;
}

void put_over_background(Image& img, Vec3f background) {
  for (Vec4f& p : img.pixels) {
    const float t = 1.0f - p.w;
    p = Vec4f{p.x + t * background.x, p.y + t * background.y, p.z + t * background.z, 1.0f};
  }
}

}  // namespace vnr::mpi
