#pragma once
// Per-ray rendering code (paper "Rendering", docs/semantics.md B.7-B.9), written once as VNR_HD functions over
// POD state so that both execution strategies -- in-shader (one ray loops over its own samples) and
// sample streaming (wavefront queues, batched field queries) -- run exactly the same arithmetic, and
// so a GPU backend can launch the same functions. Nothing here allocates, throws or calls virtually.
//
// Each integrator is a pair of functions around the field query:
//   *_next(...)  -> the next sample position of a ray (or false: the ray is done), advancing its state;
//   *_shade(...) -> consumes the field value at that position; false when the ray terminates.
#include <cmath>
#include <cstdint>
#include "vnr/hd.h"
#include "vnr/math.h"
#include "vnr/core/rng.h"
#include "vnr/render/camera.h"
#include "vnr/render/macrocell.h"
#include "vnr/render/transfer_function.h"

namespace vnr {

// Everything per-ray code reads, by value (a CUDA kernel parameter block later).
struct RenderParams {
  CameraFrame cam;
  Vec3f box{1, 1, 1};        // world size of the volume box [0, box]
  Vec3f inv_box{1, 1, 1};    // normalised coordinate u = p * inv_box
  TfView tf;
  MacroCellView mc;
  float step = 1;            // s1: base step (world units = voxels)
  float step_max = 16;       // s2: largest adaptive step (B.7); step_max = step gives uniform steps
  float min_mu = 0.1f;       // the original's clamp of the cell opacity in the step formula
  float empty_mu = 1e-6f;    // cells with max opacity at or below this are transparent
  float shadow_step = 2;     // single-shot shadow ray step (2 * s1)
  float alpha_stop = 0.9999f;
  bool shade = false;        // gradient (Phong, headlight) shading in ray marching
  Vec3f grad_h{1, 1, 1};     // central-difference offsets in normalised coordinates (one voxel)
  Vec3f light_dir = normalize(Vec3f{0.7f, 0.9f, 0.4f});  // toward the light
  Vec3f light_color{1, 1, 1};
  Vec3f background{0, 0, 0};
  float density_scale = 1;   // path tracing: extinction = alpha * density_scale per world unit
  float albedo_scale = 0.6f; // scattering albedo = albedo_scale * TF colour
  float ambient = 1.5f;      // radiance seen by a scattered ray that leaves the volume
  int rr_after = 4;          // Russian roulette after more than this many scattering events
  uint32_t seed = 0, frame = 0;
};

// Per-pixel random stream for one frame: identical in both strategies.
VNR_HD VNR_INLINE Pcg32 pixel_rng(const RenderParams& p, uint32_t pixel) {
  return Pcg32((uint64_t(p.seed) << 32) ^ (uint64_t(p.frame) * 0x9E3779B97F4A7C15ULL), pixel);
}

VNR_HD VNR_INLINE Vec3f ray_at(Vec3f o, Vec3f d, float t) { return o + d * t; }

// ---------------------------------------------------------------------------------------------------
// Stepping through macro-cells with regular steps (ray marching and single-shot shadow rays).

// The common stepping state of a marched ray.
struct StepState {
  Vec3f org, dir;
  DdaState dda;
  float t;       // start of the next step
  float jitter;  // sample offset within a step, in [0,1)
  // The non-empty cell being marched: where it ends and the step length in it (seg_end = -1: none
  // yet). Cached so that the samples after a cell's first need no DDA or opacity lookups.
  float seg_end, seg_len;
};

VNR_HD VNR_INLINE bool step_begin(const RenderParams& p, Vec3f org, Vec3f dir, float t_min, float jitter,
                                  StepState& s) {
  float t0, t1;
  if (!intersect_box(org, dir, p.box, &t0, &t1)) return false;
  t0 = t0 > t_min ? t0 : t_min;
  if (t0 >= t1) return false;
  s.org = org;
  s.dir = dir;
  s.t = t0;
  s.jitter = jitter;
  s.seg_end = -1;
  s.seg_len = 0;
  dda_init(p.mc, org, dir, t0, t1, s.dda);
  return true;
}

// Distances below this are no step (a cell the ray only grazes; the end of a used-up cell).
VNR_HD VNR_INLINE float step_eps(float fixed_step) { return 1e-5f * fixed_step; }

// Makes sure the ray has a non-empty macro-cell to step in: transparent cells are skipped; inside a
// cell with max opacity mu the step is s1 + (s2 - s1) * |min(max(mu, min_mu), 1) - 1|^2 (B.7;
// adaptive = false forces s1 = s2 = fixed_step). False once the ray has left the volume.
VNR_HD VNR_INLINE bool step_segment(const RenderParams& p, StepState& s, bool adaptive, float fixed_step) {
  const float eps = step_eps(fixed_step);
  if (s.seg_end - s.t > eps) return true;  // still inside the cached cell
  if (s.seg_end >= 0) {                    // it is used up: on to the next one
    s.t = s.seg_end > s.t ? s.seg_end : s.t;
    s.seg_end = -1;
    if (!dda_advance(p.mc, s.dda)) return false;
  }
  for (;;) {
    float t_exit = dda_cell_exit(s.dda);
    if (t_exit - s.t > eps) {
      float mu = p.mc.max_opacity[dda_cell_index(p.mc, s.dda)];
      if (mu > p.empty_mu) {
        float len = fixed_step;
        if (adaptive) {
          float m = mu < p.min_mu ? p.min_mu : (mu > 1 ? 1 : mu);
          len = p.step + (p.step_max - p.step) * (1 - m) * (1 - m);
        }
        s.seg_end = t_exit;
        s.seg_len = len;
        return true;
      }
    }
    s.t = t_exit > s.t ? t_exit : s.t;
    if (!dda_advance(p.mc, s.dda)) return false;
  }
}

// The step [ta, tb] after s.t inside the current cell (step_segment first): the last step in a cell
// ends at the cell boundary. Returns the length; *t_sample = ta + jitter * (tb - ta).
VNR_HD VNR_INLINE float step_take(StepState& s, float* t_sample) {
  float ta = s.t, tb = ta + s.seg_len < s.seg_end ? ta + s.seg_len : s.seg_end;
  s.t = tb;
  *t_sample = ta + s.jitter * (tb - ta);
  return tb - ta;
}

// Next sample of a ray: its position and step length; false when the ray has left the volume.
VNR_HD VNR_INLINE bool step_next(const RenderParams& p, StepState& s, bool adaptive, float fixed_step, Vec3f* pos,
                                 float* dt) {
  if (!step_segment(p, s, adaptive, fixed_step)) return false;
  float ts;
  *dt = step_take(s, &ts);
  *pos = ray_at(s.org, s.dir, ts);
  return true;
}

// unit_pow's constants: log2 m = kLog2Atanh atanh(t), t = (m - 1) / (m + 1), by its series to t^9; 2^f
// for |f| <= 1/2 by the degree-6 polynomial through its Chebyshev nodes (within 2e-8).
constexpr float kUnitPowSqrt2 = 1.41421356f, kLog2Atanh = 2.88539008f /* 2 / ln 2 */;
constexpr float kAtanh9 = 1.0f / 9, kAtanh7 = 1.0f / 7, kAtanh5 = 1.0f / 5, kAtanh3 = 1.0f / 3;
constexpr float kExp2C1 = 0.693147182f, kExp2C2 = 0.240226507f, kExp2C3 = 0.0555032715f, kExp2C4 = 0.00961805694f,
                kExp2C5 = 0.00134004280f, kExp2C6 = 0.000154614449f;

// b^e for b in [0, 1] (0 or a normal float, as 1 - alpha is) and e > 0: a step's transmittance, as
// 2^(e log2 b) with fixed polynomials in plain arithmetic. No libm call (the SIMD ray packets called powf
// lane by lane, through memory, on most of their steps: docs/benchmarks.md), and the same operations as
// the packets' UnitPowVec (fields/grid_packets.cpp), which equals it bit for bit. The polynomials are
// split in halves (Estrin's scheme) for a shorter chain of dependent operations.
// Within 1.5e-7 of pow, 3e-7 relative where b^e >= 1/2 (tests/test_render.cpp); 0 for b <= 0 or NaN
// and below 2^-126.
VNR_HD VNR_INLINE float unit_pow(float b, float e) {
  if (!(b > 0.0f)) return 0.0f;
  if (e == 2.0f) return b * b;  // a shadow ray's fixed step (2 s1 at s1 = 1), correctly rounded
  const uint32_t bits = __builtin_bit_cast(uint32_t, b);
  int k = int(bits >> 23) - 127;  // b = m 2^k
  float m = __builtin_bit_cast(float, (bits & 0x7fffffu) | 0x3f800000u);
  if (m > kUnitPowSqrt2) m = m * 0.5f, k = k + 1;  // m in (sqrt(1/2), sqrt(2)]
  const float t = (m - 1.0f) / (m + 1.0f), t2 = t * t;
  const float series = (kAtanh3 * t2 + 1.0f) + (t2 * t2) * ((kAtanh9 * t2 + kAtanh7) * t2 + kAtanh5);
  const float y = e * (float(k) + (t * series) * kLog2Atanh);
  if (!(y >= -126.0f)) return 0.0f;  // (and NaN)
  const float n = rintf(y), f = y - n, f2 = f * f;  // nearest integer: a small y keeps its every bit
  const float q = 1.0f + f * (((kExp2C2 * f + kExp2C1) + f2 * (kExp2C4 * f + kExp2C3)) +
                              (f2 * f2) * (kExp2C6 * f + kExp2C5));
  return q * __builtin_bit_cast(float, uint32_t(int(n) + 127) << 23);
}

// Opacity of a step of length dt from the per-voxel table opacity (B.5).
VNR_HD VNR_INLINE float corrected_alpha(float alpha, float dt) {
  alpha = alpha < 0 ? 0 : (alpha > 1 ? 1 : alpha);
  if (dt == 1.0f) return alpha;  // the common uniform step: no pow
  return 1 - unit_pow(1 - alpha, dt);
}

// ---------------------------------------------------------------------------------------------------
// Ray marching, emission-absorption (B.7), with the single-shot shadow bookkeeping (B.8).

struct MarchState {
  StepState st;
  Vec4f acc;          // premultiplied colour and alpha
  float best;         // largest contribution (1 - A) * alpha' so far
  Vec3f best_pos;     // where it was
  Vec3f best_color;   // TF colour there
};

// Starts the primary ray of pixel (ix, iy); false when it misses the volume box.
VNR_HD VNR_INLINE bool march_begin(const RenderParams& p, int ix, int iy, MarchState& s) {
  Pcg32 rng = pixel_rng(p, uint32_t(iy * p.cam.width + ix));
  float jitter = rng.next_float();
  s.acc = Vec4f{0, 0, 0, 0};
  s.best = 0;
  s.best_pos = Vec3f{0, 0, 0};
  s.best_color = Vec3f{0, 0, 0};
  Vec3f dir = camera_ray_dir(p.cam, ix, iy, 0.5f, 0.5f);
  return step_begin(p, p.cam.eye, dir, 0.0f, jitter, s.st);
}

VNR_HD VNR_INLINE bool march_next(const RenderParams& p, MarchState& s, Vec3f* pos, float* dt) {
  return step_next(p, s.st, true, p.step, pos, dt);
}

// Phong-like headlight shading: ambient 0.2, diffuse 0.7 |n.l|, specular 0.2 (n.l)^10 with the light at
// the eye (the VTK peer's material). grad = field gradient; no shading where it vanishes.
VNR_HD VNR_INLINE Vec3f shade_phong(Vec3f rgb, Vec3f grad, Vec3f view_dir) {
  float g = length(grad);
  if (!(g > 1e-6f)) return rgb;
  float nl = dot(grad, view_dir) / g;
  nl = nl < 0 ? -nl : nl;
  float spec = powf(nl, 10.0f);
  return rgb * (0.2f + 0.7f * nl) + Vec3f{0.2f, 0.2f, 0.2f} * spec;
}

// values: the n = march_points_per_sample(p) field values of march_sample_points: the sample (and,
// with shading, its six central-difference neighbours +x, -x, +y, -y, +z, -z). Returns false once
// the ray is opaque.
VNR_HD VNR_INLINE bool march_shade(const RenderParams& p, MarchState& s, Vec3f pos, float dt, const float* values,
                                   int n) {
  Vec4f c = tf_lookup(p.tf, values[0]);
  float a = corrected_alpha(c.w, dt);
  Vec3f rgb = c.rgb();
  if (n > 1) {
    Vec3f grad{values[1] - values[2], values[3] - values[4], values[5] - values[6]};
    rgb = shade_phong(rgb, grad, s.st.dir);
  }
  float w = (1 - s.acc.w) * a;
  s.acc.x += w * rgb.x;
  s.acc.y += w * rgb.y;
  s.acc.z += w * rgb.z;
  s.acc.w += w;
  if (w > s.best) {
    s.best = w;
    s.best_pos = pos;
    s.best_color = c.rgb();
  }
  return s.acc.w < p.alpha_stop;
}

VNR_HD VNR_INLINE Vec4f march_pixel(const RenderParams& p, const MarchState& s) {
  float t = 1 - s.acc.w;
  return Vec4f{s.acc.x + t * p.background.x, s.acc.y + t * p.background.y, s.acc.z + t * p.background.z, s.acc.w};
}

// The n points a sample needs: the sample itself, then (shading) its six neighbours. Callers pass
// n = march_points_per_sample(p) here and to march_shade, so one with a compile-time n = 1 drops
// the neighbour code and its arrays.
VNR_HD VNR_INLINE int march_points_per_sample(const RenderParams& p) { return p.shade ? 7 : 1; }
VNR_HD VNR_INLINE void march_sample_points(const RenderParams& p, Vec3f pos, int n, float* x, float* y, float* z) {
  Vec3f u = pos * p.inv_box;
  x[0] = u.x, y[0] = u.y, z[0] = u.z;
  if (n == 1) return;
  const float h[3] = {p.grad_h.x, p.grad_h.y, p.grad_h.z};
  for (int a = 0; a < 3; ++a)
    for (int sgn = 0; sgn < 2; ++sgn) {
      int k = 1 + 2 * a + sgn;
      float d = sgn == 0 ? h[a] : -h[a];
      x[k] = u.x + (a == 0 ? d : 0);
      y[k] = u.y + (a == 1 ? d : 0);
      z[k] = u.z + (a == 2 ? d : 0);
    }
}

// ---------------------------------------------------------------------------------------------------
// Single-shot heuristic shadow (B.8): one shadow ray from the highest-contribution sample.

struct ShadowState {
  StepState st;
  float T;  // transmittance so far
};

VNR_HD VNR_INLINE bool shadow_begin(const RenderParams& p, const MarchState& m, ShadowState& s) {
  s.T = 1;
  if (!(m.best > 0)) return false;
  return step_begin(p, m.best_pos, p.light_dir, 0.0f, m.st.jitter, s.st);
}
VNR_HD VNR_INLINE bool shadow_next(const RenderParams& p, ShadowState& s, Vec3f* pos, float* dt) {
  return step_next(p, s.st, false, p.shadow_step, pos, dt);
}
VNR_HD VNR_INLINE bool shadow_shade(const RenderParams& p, ShadowState& s, float value, float dt) {
  s.T *= 1 - corrected_alpha(tf_lookup(p.tf, value).w, dt);
  return s.T > 1 - p.alpha_stop;
}
// C_final = lerp(C, c_max * A * T, 0.95) (the original's choice).
VNR_HD VNR_INLINE Vec4f shadow_pixel(const RenderParams& p, const MarchState& m, float T) {
  Vec4f c = march_pixel(p, m);
  if (!(m.best > 0)) return c;
  const float k = 0.95f;
  Vec3f target = m.best_color * (m.acc.w * T);
  return Vec4f{c.x + (target.x - c.x) * k, c.y + (target.y - c.y) * k, c.z + (target.z - c.z) * k, c.w};
}

// ---------------------------------------------------------------------------------------------------
// Volumetric path tracing (B.9): delta tracking against per-macro-cell majorants (Hofmann et al.),
// next-event estimation toward the directional light, isotropic phase, Russian roulette. One ray per
// pixel alternates between the scattering and the shadow state (paper Fig. "path tracing algorithm
// using sample-streaming"): pt_sample is the paper's sample(), pt_shade its shade().

struct PathState {
  Vec3f org, dir;       // current segment
  DdaState dda;
  float t;              // current position along dir
  float tau;            // optical thickness still to travel before the next tentative collision
  float majorant;       // majorant at the pending tentative collision
  Vec3f pos;            // the pending tentative collision
  Vec3f throughput, L;
  Vec3f scatter_pos, scatter_dir;  // where the shadow ray left from, and the direction chosen there
  Pcg32 rng;
  int n_scatter;
  bool shadow;
};

VNR_HD VNR_INLINE float sample_tau(Pcg32& rng) { return -logf(1 - rng.next_float()); }

// Starts a segment at org along dir (org inside or outside the box).
VNR_HD VNR_INLINE void pt_start_segment(const RenderParams& p, PathState& s, Vec3f org, Vec3f dir) {
  s.org = org;
  s.dir = dir;
  s.tau = sample_tau(s.rng);
  float t0, t1;
  if (!intersect_box(org, dir, p.box, &t0, &t1) || t1 <= (t0 > 0 ? t0 : 0)) {
    t0 = t1 = 0;  // empty segment: tracking reports an escape at once
  }
  t0 = t0 > 0 ? t0 : 0;
  s.t = t0;
  dda_init(p.mc, org, dir, t0, t1, s.dda);
  if (t1 <= t0) s.dda.t_end = t0;
}

// Walks the majorant grid until the sampled optical thickness is used up: true = a tentative
// collision at s.pos (majorant in s.majorant); false = the segment left the volume.
VNR_HD VNR_INLINE bool pt_track(const RenderParams& p, PathState& s) {
  for (;;) {
    float t_exit = dda_cell_exit(s.dda);
    if (t_exit > s.t) {
      float m = p.mc.max_opacity[dda_cell_index(p.mc, s.dda)] * p.density_scale;
      float seg = t_exit - s.t;
      if (m > 0 && m * seg >= s.tau) {
        s.t += s.tau / m;
        s.tau = 0;
        s.majorant = m;
        s.pos = ray_at(s.org, s.dir, s.t);
        return true;
      }
      if (m > 0) s.tau -= m * seg;
      s.t = t_exit;
    }
    if (!dda_advance(p.mc, s.dda)) return false;
  }
}

VNR_HD VNR_INLINE Vec3f sample_sphere(Pcg32& rng) {
  float z = 1 - 2 * rng.next_float();
  float r = sqrtf(z > 1 ? 0 : 1 - z * z);
  float phi = 6.28318530718f * rng.next_float();
  return Vec3f{r * cosf(phi), r * sinf(phi), z};
}

// Starts the path of pixel (ix, iy) (sub-pixel jitter per frame); false when it misses the box.
VNR_HD VNR_INLINE bool pt_begin(const RenderParams& p, int ix, int iy, PathState& s) {
  s.rng = pixel_rng(p, uint32_t(iy * p.cam.width + ix));
  float jx = s.rng.next_float(), jy = s.rng.next_float();
  s.throughput = Vec3f{1, 1, 1};
  s.L = Vec3f{0, 0, 0};
  s.n_scatter = 0;
  s.shadow = false;
  Vec3f dir = camera_ray_dir(p.cam, ix, iy, jx, jy);
  float t0, t1;
  if (!intersect_box(p.cam.eye, dir, p.box, &t0, &t1) || t1 <= (t0 > 0 ? t0 : 0)) {
    s.L = p.background;
    return false;
  }
  pt_start_segment(p, s, p.cam.eye, dir);
  return true;
}

// The paper's sample(): finds the next point where the field is needed. Handles escapes: a shadow
// ray that escapes adds the light and turns back into the scattering ray; a scattering ray that
// escapes adds the ambient light (or the background for a primary ray) and ends the path (false).
VNR_HD VNR_INLINE bool pt_sample(const RenderParams& p, PathState& s) {
  for (;;) {
    if (pt_track(p, s)) return true;
    if (s.shadow) {
      s.L = s.L + s.throughput * p.light_color;
      s.shadow = false;
      pt_start_segment(p, s, s.scatter_pos, s.scatter_dir);
      continue;
    }
    s.L = s.L + (s.n_scatter > 0 ? s.throughput * p.ambient : p.background);
    return false;
  }
}

// The paper's shade(): consumes the field value at the tentative collision. Null collision: keep
// tracking. Real collision of a shadow ray: the light is blocked, back to the scattering ray. Real
// collision of a scattering ray: Russian roulette, albedo, then a shadow ray toward the light (the new
// scattering direction is drawn now and used when the shadow ray is done). false = the path ended.
VNR_HD VNR_INLINE bool pt_shade(const RenderParams& p, PathState& s, float value) {
  Vec4f c = tf_lookup(p.tf, value);
  float sigma = (c.w < 0 ? 0 : c.w) * p.density_scale;
  if (s.rng.next_float() * s.majorant >= sigma) {  // null collision
    s.tau = sample_tau(s.rng);
    return true;
  }
  if (s.shadow) {
    s.shadow = false;
    pt_start_segment(p, s, s.scatter_pos, s.scatter_dir);
    return true;
  }
  s.n_scatter += 1;
  if (s.n_scatter > p.rr_after) {
    float q = max_component(s.throughput);
    q = q < 0.95f ? q : 0.95f;
    if (s.rng.next_float() >= q) return false;
    s.throughput = s.throughput * (1.0f / q);
  }
  s.throughput = s.throughput * (c.rgb() * p.albedo_scale);
  s.scatter_pos = s.pos;
  s.scatter_dir = sample_sphere(s.rng);
  s.shadow = true;
  pt_start_segment(p, s, s.pos, p.light_dir);
  return true;
}

VNR_HD VNR_INLINE Vec4f pt_pixel(const PathState& s) { return Vec4f{s.L.x, s.L.y, s.L.z, 1}; }

}  // namespace vnr
