#pragma once
// In-shader ray marching of the ground-truth grid with rays in SIMD packets: the CPU counterpart of a
// GPU warp running the in-shader loop. Each lane is one ray; every lane executes exactly the scalar
// operations of integrators.h (step_segment / step_take, grid_lookup, tf_lookup, corrected_alpha,
// the compositing of march_shade), so the image equals the per-ray loop's bit for bit. A lane whose
// ray ends takes the next pixel at once, so lanes stay busy. Macro-cell traversal stays scalar per lane.
#include <cstddef>
#include <cstdint>
#include "vnr/grid_view.h"
#include "vnr/hd.h"
#include "vnr/render/inshader.h"
#include "vnr/render/integrators.h"
#include "vnr/render/tiles.h"

namespace vnr {

// Whether march_grid_packets can render this frame: unshaded ray marching of a volume below 2^31
// voxels (32-bit gather indices) and at least 2 voxels wide in x (x-neighbours load as pairs).
inline bool grid_packets_apply(const RenderParams& p, const GridView& g) {
  return !p.shade && g.nx >= 2 && grid_fits_gather_indices(g);
}

// Ray marches (RenderMode::RayMarch, unshaded) the cursor's pixels into pixels[y * width + x];
// returns the number of field samples taken.
int64_t march_grid_packets(const RenderParams& p, const GridView& g, TileCursor cursor, Vec4f* pixels);

struct BrickCacheView;    // render/brick_cache_view.h
class RenderableField;    // fields/fields.h
// Whether march_cache_packets can render this frame: unshaded ray marching, every level at least 2
// voxels wide in x.
bool cache_packets_apply(const RenderParams& p, const BrickCacheView& c);
// The same packets over the brick cache (BrickCacheView::sample per lane, bit for bit; a miss reads
// `source`, the model's field, one point at a time).
int64_t march_cache_packets(const RenderParams& p, const BrickCacheView& c, const RenderableField& source,
                            TileCursor cursor, Vec4f* pixels);

// out[i] = unit_pow(b[i], e[i]) as the packets compute it (UnitPowVec; for tests).
void unit_pow_packets(const float* b, const float* e, float* out, size_t n);

// The ground-truth grid's point function.
struct GridPointFn {
  GridView g;
  VNR_HD VNR_INLINE float operator()(float x, float y, float z) const { return grid_lookup(g, x, y, z); }
};

// The grid's in-shader frame: SIMD ray packets where they apply and the job allows them, else
// render's run_inshader with GridPointFn. Returns the number of field samples.
int64_t run_inshader_grid(const InshaderJob& job, const GridView& g);

}  // namespace vnr
