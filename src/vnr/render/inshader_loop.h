#pragma once
// The in-shader strategy's per-pixel loop, written once for every backend: a pixel's whole ray runs
// begin -> next -> point query -> shade (ray marching, + the single-shot shadow ray, or the path
// tracer's sample()/shade() state machine). The CPU renderer calls it per pixel (inshader.h), the
// GPU's in-shader kernels per thread (render_cuda/inshader_kernels.cuh).
//
// The field is a *lane evaluator* `Eval`: lanes are the rays of a group that evaluate the field
// together (a GPU warp, whose network evaluation is warp-cooperative; one ray on the CPU). It has
//   bool any(bool active)                        -- whether any lane of the group is still active;
//   float operator()(bool active, x, y, z)       -- the value at (x, y, z), called by every lane of
//                                                   the group together (`active`: whose sample counts).
// Every lane stays in the loops until its whole group is done; an inactive lane only evaluates along.
#include <cstdint>
#include "vnr/hd.h"
#include "vnr/render/integrators.h"

// The per-pixel templates are __host__ __device__ but may be instantiated with a device-only
// evaluator (warp intrinsics): VNR_HD_TEMPLATE (core/hd.h).

namespace vnr {

// A single ray as its own group (the CPU): a point function f(x, y, z) as a lane evaluator.
template <class PointFn>
struct SingleRayEval {
  const PointFn& f;
  VNR_HD VNR_INLINE bool any(bool active) const { return active; }
  VNR_HD VNR_INLINE float operator()(bool, float x, float y, float z) const { return f(x, y, z); }
};

// Ray marching of pixel (ix, iy) with M field points per sample (1, or 7 with shading: a compile-time
// M keeps an unshaded sample out of the 7-point arrays), plus its single-shot shadow ray when
// `shadow`. Adds the lane's field samples to *samples; the pixel's colour (meaningless when
// !in_image: an out-of-image lane only takes part in its group's evaluations).
VNR_HD_TEMPLATE
template <int M, class Eval>
VNR_HD VNR_INLINE Vec4f inshader_march_pixel(const RenderParams& p, const Eval& eval, int ix, int iy, bool in_image,
                                             bool shadow, int64_t* samples) {
  MarchState s;
  s.st.jitter = 0;  // set by march_begin when it succeeds; zeroed so no compiler sees a maybe-uninitialised read
  const bool began = in_image && march_begin(p, ix, iy, s);
  bool active = began;
  Vec3f pos{0, 0, 0};
  float dt = 0;
  int64_t my = 0;
  for (;;) {
    if (active) active = march_next(p, s, &pos, &dt);
    if (!eval.any(active)) break;
    float x[M], y[M], z[M], v[M];
    march_sample_points(p, pos, M, x, y, z);
    for (int k = 0; k < M; ++k) v[k] = eval(active, x[k], y[k], z[k]);
    if (active) {
      my += M;
      active = march_shade(p, s, pos, dt, v, M);
    }
  }
  Vec4f pixel;
  if (shadow) {
    ShadowState sh;
    sh.T = 1;
    active = began && shadow_begin(p, s, sh);  // a ray that missed the box has no shadow ray
    for (;;) {
      if (active) active = shadow_next(p, sh, &pos, &dt);
      if (!eval.any(active)) break;
      const Vec3f u = pos * p.inv_box;
      const float v = eval(active, u.x, u.y, u.z);
      if (active) {
        my += 1;
        active = shadow_shade(p, sh, v, dt);
      }
    }
    pixel = in_image ? shadow_pixel(p, s, sh.T) : Vec4f{0, 0, 0, 0};
  } else {
    pixel = in_image ? march_pixel(p, s) : Vec4f{0, 0, 0, 0};
  }
  *samples += my;
  return pixel;
}

// Path tracing of pixel (ix, iy): the sample()/shade() state machine of one path (see above).
VNR_HD_TEMPLATE
template <class Eval>
VNR_HD VNR_INLINE Vec4f inshader_path_pixel(const RenderParams& p, const Eval& eval, int ix, int iy, bool in_image,
                                            int64_t* samples) {
  PathState s;
  bool active = in_image && pt_begin(p, ix, iy, s) && pt_sample(p, s);
  int64_t my = 0;
  for (;;) {
    if (!eval.any(active)) break;
    const Vec3f u = active ? s.pos * p.inv_box : Vec3f{0, 0, 0};
    const float v = eval(active, u.x, u.y, u.z);
    if (active) {
      my += 1;
      active = pt_shade(p, s, v) && pt_sample(p, s);
    }
  }
  *samples += my;
  return in_image ? pt_pixel(s) : Vec4f{0, 0, 0, 0};
}

}  // namespace vnr
