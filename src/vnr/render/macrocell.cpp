#include "vnr/render/macrocell.h"
#include <algorithm>
#include "vnr/core/parallel.h"
#include "vnr/error.h"
#include "vnr/json.h"

namespace vnr {

MacroCellMode parse_macrocell_mode(const std::string& s) {
  std::string l = to_lower(s);
  if (l == "grid") return MacroCellMode::Grid;
  if (l == "online") return MacroCellMode::Online;
  if (l == "off" || l == "none") return MacroCellMode::Off;
  fail("unknown macro-cell mode '{}' (expected grid, online or off)", s);
}

const char* macrocell_mode_name(MacroCellMode m) {
  return m == MacroCellMode::Grid ? "grid" : (m == MacroCellMode::Online ? "online" : "off");
}

MacroCells::MacroCells(ValueRangeGrid ranges, Vec3f box) : ranges_(std::move(ranges)), box_(box) {
  const Int3& d = ranges_.volume_dims;
  // A cell covers cell_size voxels of world size box / dims each (the last one may overhang the box).
  cell_world_ = Vec3f{box.x / float(d.x) * float(ranges_.cell_size), box.y / float(d.y) * float(ranges_.cell_size),
                      box.z / float(d.z) * float(ranges_.cell_size)};
  max_opacity_.assign(size_t(ranges_.count()), 1.0f);
}

MacroCells MacroCells::single(Int3 dims, Vec3f box, float lo, float hi) {
  int64_t cs = std::max({dims.x, dims.y, dims.z});
  ValueRangeGrid g(dims, int(cs));
  g.lo.assign(1, lo);
  g.hi.assign(1, hi);
  return MacroCells(std::move(g), box);
}

void MacroCells::update(const TransferFunction& tf) {
  const int n = int(tf.table.size());
  const float w = tf.hi - tf.lo;
  // Cells on every thread: a viewer recomputes them after every training chunk.
  parallel_for_range(ranges_.count(), 1024, [&](int64_t begin, int64_t end) {
    for (int64_t c = begin; c < end; ++c)
      max_opacity_[c] = macrocell_max_opacity(tf.table.data(), n, tf.lo, w, ranges_.lo[c], ranges_.hi[c]);
  });
}

MacroCellView MacroCells::view() const {
  MacroCellView v;
  v.max_opacity = max_opacity_.data();
  v.nx = int32_t(ranges_.cells.x);
  v.ny = int32_t(ranges_.cells.y);
  v.nz = int32_t(ranges_.cells.z);
  v.cell_world = cell_world_;
  v.inv_cell_world = Vec3f{1.0f / cell_world_.x, 1.0f / cell_world_.y, 1.0f / cell_world_.z};
  return v;
}

double MacroCells::empty_fraction() const {
  int64_t e = 0;
  for (float m : max_opacity_) e += m <= 0;
  return max_opacity_.empty() ? 0.0 : double(e) / double(max_opacity_.size());
}

}  // namespace vnr
