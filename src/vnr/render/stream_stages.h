#pragma once
// The sample-streaming strategy's stages, written once for every backend as per-slot functors over
// POD device/host pointers: `operator()(i)` does the work of one pixel or one live-queue slot. The CPU
// renderer runs them with parallel_for over host arrays (renderer.cpp), the GPU renderer as kernels
// over GPU memory (core/parallel.h's CUDA parallel_for, render_cuda/gpu_renderer.cu); only the queue
// bookkeeping around them (scan, compaction, synchronisation) is the backend's.
//
// One iteration of a pass over the live queue live[0, n_live) (indices of rays into the state arrays):
//   StreamNext  -- up to K samples per live ray: positions and steps in slots r*K.., count[r];
//   (the backend scans count into offset)
//   StreamEmit  -- the samples' field points (1, or 7 with shading) at their packed offsets;
//   (one batched field query over the packed points)
//   StreamShade -- consumes the values; keep[r] = the ray goes on (it used all K samples);
//   (the backend compacts live by keep)
// The per-ray work of a pass is an Ops POD (MarchOps: primary rays; ShadowOps: shadow rays).
#include <cstdint>
#include "vnr/hd.h"
#include "vnr/render/integrators.h"

namespace vnr {

// The most field points one sample needs (a shaded ray-marching sample and its six neighbours).
constexpr int kMaxPointsPerSample = 7;

struct MarchOps {
  MarchState* s;
  int m;  // points per sample (1, or 7 with shading)
  VNR_HD VNR_INLINE bool next(const RenderParams& p, int32_t i, Vec3f* pos, float* dt) const {
    return march_next(p, s[i], pos, dt);
  }
  VNR_HD VNR_INLINE void points(const RenderParams& p, Vec3f pos, float* x, float* y, float* z) const {
    march_sample_points(p, pos, m, x, y, z);
  }
  VNR_HD VNR_INLINE bool shade(const RenderParams& p, int32_t i, Vec3f pos, float dt, const float* v) const {
    return march_shade(p, s[i], pos, dt, v, m);
  }
};

struct ShadowOps {
  ShadowState* s;
  static constexpr int m = 1;
  VNR_HD VNR_INLINE bool next(const RenderParams& p, int32_t i, Vec3f* pos, float* dt) const {
    return shadow_next(p, s[i], pos, dt);
  }
  VNR_HD VNR_INLINE void points(const RenderParams& p, Vec3f pos, float* x, float* y, float* z) const {
    const Vec3f u = pos * p.inv_box;
    *x = u.x, *y = u.y, *z = u.z;
  }
  VNR_HD VNR_INLINE bool shade(const RenderParams& p, int32_t i, Vec3f, float dt, const float* v) const {
    return shadow_shade(p, s[i], v[0], dt);
  }
};

// Packed field points: point q at (x[q * stride], y[q * stride], z[q * stride]) -- three arrays
// (stride 1) or one interleaved xyz array (x = xyz, y = xyz + 1, z = xyz + 2, stride 3).
struct PointSink {
  float *x, *y, *z;
  int stride;
  VNR_HD VNR_INLINE void put(int64_t q, float px, float py, float pz) const {
    x[q * stride] = px;
    y[q * stride] = py;
    z[q * stride] = pz;
  }
};

// ---------------------------------------------------------------------------------------------------
// Ray generation (one pixel each) and the final pixels.

struct MarchBeginStage {
  RenderParams p;
  MarchState* s;
  uint8_t* keep;
  VNR_HD VNR_INLINE void operator()(int64_t i) const {
    keep[i] = march_begin(p, int(i % p.cam.width), int(i / p.cam.width), s[i]);
  }
};

struct ShadowBeginStage {
  RenderParams p;
  const MarchState* march;
  ShadowState* s;
  uint8_t* keep;
  VNR_HD VNR_INLINE void operator()(int64_t i) const { keep[i] = shadow_begin(p, march[i], s[i]); }
};

// The ray-marched pixels, with their shadow rays' transmittance when shadow != nullptr.
struct MarchPixelStage {
  RenderParams p;
  const MarchState* march;
  const ShadowState* shadow;
  Vec4f* img;
  VNR_HD VNR_INLINE void operator()(int64_t i) const {
    img[i] = shadow ? shadow_pixel(p, march[i], shadow[i].T) : march_pixel(p, march[i]);
  }
};

// Path tracing: ray generation absorbs the first sample() (paper: raygen_kernel<PT_RAY>); a path that
// ends at once writes its pixel.
struct PathBeginStage {
  RenderParams p;
  PathState* s;
  uint8_t* keep;
  Vec4f* img;
  VNR_HD VNR_INLINE void operator()(int64_t i) const {
    const bool k = pt_begin(p, int(i % p.cam.width), int(i / p.cam.width), s[i]) && pt_sample(p, s[i]);
    keep[i] = k;
    if (!k) img[i] = pt_pixel(s[i]);
  }
};

// ---------------------------------------------------------------------------------------------------
// Ray marching passes (primary and shadow rays).

// Coordinate stage: up to K samples of live ray r < *n_live; count[r] = 0 for slots past it (a GPU
// launches over an upper bound of the live count and reads the exact one from its memory).
template <class Ops>
struct StreamNext {
  RenderParams p;
  Ops ops;
  const int32_t* live;
  const int* n_live;
  int K;
  Vec3f* spos;
  float* sdt;
  int64_t* count;
  VNR_HD VNR_INLINE void operator()(int64_t r) const {
    int c = 0;
    if (r < *n_live) {
      const int32_t i = live[r];
      while (c < K && ops.next(p, i, &spos[r * K + c], &sdt[r * K + c])) ++c;
    }
    count[r] = c;
  }
};

// Packs slot r's samples' field points at their scanned offsets (ops.m points per sample).
template <class Ops>
struct StreamEmit {
  RenderParams p;
  Ops ops;
  int K;
  const Vec3f* spos;
  const int64_t* count;
  const int64_t* offset;
  PointSink out;
  VNR_HD VNR_INLINE void operator()(int64_t r) const {
    for (int k = 0; k < int(count[r]); ++k) {
      float x[kMaxPointsPerSample], y[kMaxPointsPerSample], z[kMaxPointsPerSample];
      ops.points(p, spos[r * K + k], x, y, z);
      const int64_t q = (offset[r] + k) * ops.m;
      for (int j = 0; j < ops.m; ++j) out.put(q + j, x[j], y[j], z[j]);
    }
  }
};

// Shading stage: consumes slot r's values (value of point q at values[q * stride]); keep[r] = the ray
// goes on (it used all K slots and did not terminate).
template <class Ops>
struct StreamShade {
  RenderParams p;
  Ops ops;
  const int32_t* live;
  int K;
  const Vec3f* spos;
  const float* sdt;
  const int64_t* count;
  const int64_t* offset;
  const float* values;
  int stride;
  uint8_t* keep;
  VNR_HD VNR_INLINE void operator()(int64_t r) const {
    const int32_t i = live[r];
    const int c = int(count[r]);
    bool alive = c == K;
    for (int k = 0; k < c; ++k) {
      float v[kMaxPointsPerSample];
      const int64_t q = (offset[r] + k) * ops.m;
      for (int j = 0; j < ops.m; ++j) v[j] = values[(q + j) * stride];
      if (!ops.shade(p, i, spos[r * K + k], sdt[r * K + k], v)) {
        alive = false;
        break;
      }
    }
    keep[r] = alive;
  }
};

// ---------------------------------------------------------------------------------------------------
// Path tracing passes: one field point per live path per iteration.

// The pending collision of live path r as a field point; slots in [n_live, n) are padding (zero).
struct PathCoords {
  RenderParams p;
  const PathState* s;
  const int32_t* live;
  int64_t n_live;
  PointSink out;
  VNR_HD VNR_INLINE void operator()(int64_t r) const {
    const Vec3f u = r < n_live ? s[live[r]].pos * p.inv_box : Vec3f{0, 0, 0};
    out.put(r, u.x, u.y, u.z);
  }
};

// shade() and the next sample() of live path r; a path that ends writes its pixel.
struct PathShade {
  RenderParams p;
  PathState* s;
  const int32_t* live;
  const float* values;
  int stride;
  uint8_t* keep;
  Vec4f* img;
  VNR_HD VNR_INLINE void operator()(int64_t r) const {
    const int32_t i = live[r];
    const bool k = pt_shade(p, s[i], values[r * stride]) && pt_sample(p, s[i]);
    keep[r] = k;
    if (!k) img[i] = pt_pixel(s[i]);
  }
};

}  // namespace vnr
