#pragma once
// What the brick-cache tests share: a grid source's decode, cache settings that read level 0, a bit-exact
// image comparison, a scene and a frame's parameters.
#include <cstdint>
#include "vnr/core/value_range_grid.h"
#include "vnr/fields/brick_cache.h"
#include "vnr/render/macrocell.h"
#include "vnr/render/transfer_function.h"
#include "vnr/render/integrators.h"
#include "vnr/render/renderer.h"
#include "test_support.h"

namespace vnr::test {

// The decode of a grid source: its own voxels at its dims, else the grid sampled at the voxel centres.
inline VoxelDecode grid_decode(const Volume& vol) {
  return [&vol](Int3 dims, const int64_t* index, int64_t n, float* out) {
    for (int64_t i = 0; i < n; ++i) {
      if (dims == vol.dims) {
        out[i] = vol.data[size_t(index[i])];
        continue;
      }
      const int64_t x = index[i] % dims.x, y = (index[i] / dims.x) % dims.y, z = index[i] / (int64_t(dims.x) * dims.y);
      out[i] = grid_lookup(view_of(vol), (float(x) + 0.5f) / float(dims.x), (float(y) + 0.5f) / float(dims.y),
                           (float(z) + 0.5f) / float(dims.z));
    }
  };
}

inline BrickCacheSettings level0(int brick, uint64_t budget = uint64_t(64) << 20) {
  BrickCacheSettings s;
  s.brick = brick;
  s.budget_bytes = budget;
  s.lod_pixels = 1e-6f;  // every voxel is far below a pixel: level 0 everywhere
  s.decode_seconds = 1e-9;  // one brick a frame: frames render from a partly warm cache
  return s;
}

inline bool same_image(const Image& a, const Image& b) {
  for (size_t i = 0; i < a.pixels.size(); ++i) {
    const Vec4f &p = a.pixels[i], &q = b.pixels[i];
    if (!(p.x == q.x && p.y == q.y && p.z == q.z && p.w == q.w)) return false;
  }
  return a.pixels.size() == b.pixels.size();
}

// The ramp transfer function over a volume's macro-cells of 8 voxels, and in-shader options of w x h.
struct RampScene {
  TransferFunction tf = tf_preset("ramp");
  MacroCells mc;
  RenderOptions o;
  RampScene(const Volume& vol, int w, int h) : mc(value_ranges_from_grid(view_of(vol), 8), box_of(vol)) {
    mc.update(tf);
    o.width = w, o.height = h;
    o.strategy = RenderStrategy::InShader;
  }
};

inline RenderParams params_for(const Camera& cam, Int3 dims, int width, int height) {
  RenderParams p;
  p.cam = make_camera_frame(cam, width, height);
  p.box = Vec3f{float(dims.x), float(dims.y), float(dims.z)};
  return p;
}

}  // namespace vnr::test
