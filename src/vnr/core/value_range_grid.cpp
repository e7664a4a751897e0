#include "vnr/core/value_range_grid.h"
#include <algorithm>
#include <cmath>
#include <limits>
#include "vnr/error.h"
#include "vnr/core/parallel.h"

namespace vnr {

namespace {
constexpr float kInf = std::numeric_limits<float>::infinity();
}

ValueRangeGrid::ValueRangeGrid(Int3 dims, int cs) : volume_dims(dims), cell_size(cs) {
  if (cs < 1) fail("macro-cell size must be at least 1 voxel (got {})", cs);
  for (int a = 0; a < 3; ++a) {
    if (dims[a] < 1) fail("macro-cell grid: invalid volume dims");
    cells[a] = (dims[a] + cs - 1) / cs;
  }
  clear();
}

void ValueRangeGrid::clear() {
  lo.assign(size_t(count()), kInf);
  hi.assign(size_t(count()), -kInf);
}

void ValueRangeGrid::add(float px, float py, float pz, float v) {
  const float p[3] = {px, py, pz};
  int32_t c0[3], c1[3];
  const float inv = 1.0f / float(cell_size);
  for (int a = 0; a < 3; ++a) value_range_cells(p[a], inv, int32_t(cells[a]), &c0[a], &c1[a]);
  for (int64_t z = c0[2]; z <= c1[2]; ++z)
    for (int64_t y = c0[1]; y <= c1[1]; ++y)
      for (int64_t x = c0[0]; x <= c1[0]; ++x) {
        int64_t c = x + cells.x * (y + cells.y * z);
        lo[c] = std::min(lo[c], v);
        hi[c] = std::max(hi[c], v);
      }
}

void ValueRangeGrid::add_samples(const float* ux, const float* uy, const float* uz, const float* v, int64_t n) {
  const float sx = float(volume_dims.x), sy = float(volume_dims.y), sz = float(volume_dims.z);
  for (int64_t i = 0; i < n; ++i) add(ux[i] * sx, uy[i] * sy, uz[i] * sz, v[i]);
}

void ValueRangeGrid::merge(const ValueRangeGrid& o) {
  if (!(o.cells == cells)) fail("cannot merge macro-cell grids of different sizes");
  for (int64_t c = 0; c < count(); ++c) {
    lo[c] = std::min(lo[c], o.lo[c]);
    hi[c] = std::max(hi[c], o.hi[c]);
  }
}

std::vector<float> ValueRangeGrid::to_pairs() const {
  std::vector<float> out(2 * size_t(count()));
  for (int64_t c = 0; c < count(); ++c) {
    bool e = empty(c);
    out[2 * c] = e ? 1.0f : lo[c];
    out[2 * c + 1] = e ? -1.0f : hi[c];
  }
  return out;
}

ValueRangeGrid ValueRangeGrid::from_pairs(Int3 dims, Int3 cells, const std::vector<float>& pairs) {
  ValueRangeGrid g;
  g.volume_dims = dims;
  g.cells = cells;
  if (cells.count() == 0 || pairs.size() != 2 * cells.count()) fail("macro-cell ranges: wrong size");
  // The cell size is implied: the smallest size that gives these cell counts on every axis.
  int64_t cs = 1;
  for (int a = 0; a < 3; ++a) cs = std::max<int64_t>(cs, (dims[a] + cells[a] - 1) / cells[a]);
  for (int a = 0; a < 3; ++a)
    if ((dims[a] + cs - 1) / cs != cells[a])
      fail("macro-cell grid {}x{}x{} does not match volume {}x{}x{}", cells.x, cells.y, cells.z, dims.x, dims.y,
           dims.z);
  g.cell_size = int(cs);
  g.lo.resize(cells.count());
  g.hi.resize(cells.count());
  for (size_t c = 0; c < cells.count(); ++c) {
    float a = pairs[2 * c], b = pairs[2 * c + 1];
    if (!(a <= b)) a = kInf, b = -kInf;  // empty
    g.lo[c] = a;
    g.hi[c] = b;
  }
  return g;
}

ValueRangeGrid value_ranges_from_grid(const GridView& g, int cell_size) {
  ValueRangeGrid out(Int3{g.nx, g.ny, g.nz}, cell_size);
  // Each cell is reduced on its own (parallel over cells, no write sharing).
  parallel_for(out.count(), [&](int64_t c) {
    const int64_t cx = c % out.cells.x, cy = (c / out.cells.x) % out.cells.y, cz = c / (out.cells.x * out.cells.y);
    cell_value_range(g, cell_size, int32_t(cx), int32_t(cy), int32_t(cz), &out.lo[c], &out.hi[c]);
  });
  return out;
}

}  // namespace vnr
