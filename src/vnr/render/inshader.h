#pragma once
// The CPU backend's in-shader driver: every pixel runs the shared per-pixel loop of inshader_loop.h
// with the field's point function, pixels in 8x8 tiles dealt round-robin to threads (neighbouring
// rays read neighbouring voxels). A Field hands its point function over in Field::render_inshader.
#include <atomic>
#include <cstdint>
#include "vnr/core/parallel.h"
#include "vnr/render/inshader_loop.h"
#include "vnr/render/renderer.h"
#include "vnr/render/tiles.h"

namespace vnr {

// One in-shader frame: what the driver needs besides the field.
struct InshaderJob {
  const RenderParams* params;
  RenderMode mode;
  bool ray_packets;  // RenderOptions::ray_packets
  Vec4f* pixels;     // width x height of params->cam, row 0 = top
};

constexpr int kInshaderTile = 8;  // pixels per side of the tiles rays are grouped in

// One pixel of the frame: the mode's per-pixel loop (M chosen per pixel, as the options allow both).
template <class Eval>
VNR_INLINE Vec4f inshader_pixel(const RenderParams& p, RenderMode mode, const Eval& eval, int ix, int iy,
                                int64_t* samples) {
  if (mode == RenderMode::PathTrace) return inshader_path_pixel(p, eval, ix, iy, true, samples);
  const bool shadow = mode == RenderMode::Shadow;
  if (march_points_per_sample(p) == 1) return inshader_march_pixel<1>(p, eval, ix, iy, true, shadow, samples);
  return inshader_march_pixel<7>(p, eval, ix, iy, true, shadow, samples);
}

// Renders the job's frame with point function f(x, y, z); returns the number of field samples. Each
// thread calls its own copy of f (state of its own, as a GPU thread's evaluator: BrickCacheCopyReads::Memo).
template <class PointFn>
int64_t run_inshader(const InshaderJob& job, const PointFn& f) {
  const RenderParams& p = *job.params;
  const int W = p.cam.width, H = p.cam.height;
  std::atomic<int64_t> samples{0}, next_tile{0};
  parallel_threads([&](int, int) {
    const PointFn mine = f;
    const SingleRayEval<PointFn> eval{mine};
    int64_t my_samples = 0;
    TileCursor pixels{W, H, kInshaderTile, 0, 1, &next_tile};
    for (int ix, iy; pixels.next(&ix, &iy);)
      job.pixels[int64_t(iy) * W + ix] = inshader_pixel(p, job.mode, eval, ix, iy, &my_samples);
    samples += my_samples;
  });
  return samples.load();
}

}  // namespace vnr
