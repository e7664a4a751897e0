// Sort-last rendering of multi-brick models: one brick's segment of every ray, and the compositing of
// the segments (include/vnr/bricks.h).
#include <algorithm>
#include <limits>
#include "vnr/bricks.h"
#include "vnr/error.h"
#include "vnr/core/parallel.h"
#include "vnr/fields/fields.h"
#include "vnr/render/integrators.h"

namespace vnr {

namespace {
// The brick owning a sample: lo <= p < hi per axis, the volume's far faces included in the last brick.
bool owns(const Box3& b, Int3 dims, Vec3f pos) {
  const float p[3] = {pos.x, pos.y, pos.z};
  for (int a = 0; a < 3; ++a)
    if (p[a] < float(b.lo[a]) || (p[a] >= float(b.hi[a]) && b.hi[a] != dims[a])) return false;
  return true;
}
}  // namespace

BrickSegment render_brick_segment(Renderer& r, int index) {
  const Model* m = r.model();
  if (!m || !m->bricks) fail("render_brick_segment needs a multi-brick model");
  const BrickPlan& plan = m->bricks->plan;
  if (index < 0 || size_t(index) >= plan.bricks.size()) fail("brick {} is not in the model (0..{})", index, plan.bricks.size() - 1);
  if (r.options_.mode != RenderMode::RayMarch)
    fail("sort-last compositing covers ray marching without shadows (--mode raymarch), not {}",
         render_mode_name(r.options_.mode));
  // The model's own field (not the brick cache): a multi-brick model's blended bricks on the CPU.
  if (r.device() != Device::Cpu)
    fail("render_brick_segment renders on the CPU (the renderer is on {})", device_name(r.device()));
  const RenderableField* field = &r.source_field();
  const RenderParams p = make_render_params(m->dims, r.box_, r.macrocells(), r.tf_, r.camera_, r.options_);
  const Box3 owned = plan.bricks[size_t(index)].owned;
  BrickSegment seg;
  seg.index = index;
  seg.rgba = Image(p.cam.width, p.cam.height);
  seg.t_first.assign(size_t(p.cam.width) * size_t(p.cam.height), std::numeric_limits<float>::infinity());
  const int n = march_points_per_sample(p);
  parallel_for_range(p.cam.height, 1, [&](int64_t y0, int64_t y1) {
    for (int iy = int(y0); iy < int(y1); ++iy)
      for (int ix = 0; ix < p.cam.width; ++ix) {
        MarchState s;
        if (!march_begin(p, ix, iy, s)) continue;
        float t_first = std::numeric_limits<float>::infinity();
        Vec3f pos{0, 0, 0};
        float dt = 0, x[7], y[7], z[7], v[7];
        while (march_next(p, s, &pos, &dt)) {
          if (!owns(owned, m->dims, pos)) continue;  // another brick's sample
          if (t_first == std::numeric_limits<float>::infinity()) t_first = s.st.t;
          march_sample_points(p, pos, n, x, y, z);
          for (int k = 0; k < n; ++k) v[k] = field->point(x[k], y[k], z[k]);
          if (!march_shade(p, s, pos, dt, v, n)) break;
        }
        seg.rgba.at(ix, iy) = s.acc;
        seg.t_first[size_t(iy) * size_t(p.cam.width) + size_t(ix)] = t_first;
      }
  });
  return seg;
}

Image composite_brick_segments(const std::vector<const BrickSegment*>& segments, Vec3f background) {
  if (segments.empty()) fail("no segments to composite");
  const int w = segments[0]->rgba.width, h = segments[0]->rgba.height;
  for (const BrickSegment* s : segments)
    if (s->rgba.width != w || s->rgba.height != h) fail("segments of different image sizes cannot be composited");
  Image out(w, h);
  std::vector<const BrickSegment*> order;
  for (size_t i = 0; i < size_t(w) * size_t(h); ++i) {
    order = segments;
    std::stable_sort(order.begin(), order.end(),
                     [&](const BrickSegment* a, const BrickSegment* b) { return a->t_first[i] < b->t_first[i]; });
    Vec4f acc{0, 0, 0, 0};
    for (const BrickSegment* s : order) {
      const Vec4f c = s->rgba.pixels[i];
      const float t = 1 - acc.w;
      acc = Vec4f{acc.x + t * c.x, acc.y + t * c.y, acc.z + t * c.z, acc.w + t * c.w};
    }
    const float t = 1 - acc.w;
    out.pixels[i] = Vec4f{acc.x + t * background.x, acc.y + t * background.y, acc.z + t * background.z, acc.w};
  }
  return out;
}

}  // namespace vnr
