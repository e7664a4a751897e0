#include "vnr/render/renderer.h"
#include <atomic>
#include <chrono>
#include <type_traits>
#include "vnr/core/error.h"
#include "vnr/core/json.h"
#include "vnr/core/parallel.h"
#include "vnr/render/grid_packets.h"
#include "vnr/render/tiles.h"

namespace vnr {

namespace {
constexpr int kTile = 8;  // pixels per side of the tiles rays are grouped in
}  // namespace

RenderMode parse_render_mode(const std::string& s) {
  std::string l = to_lower(s);
  if (l == "raymarch") return RenderMode::RayMarch;
  if (l == "shadow") return RenderMode::Shadow;
  if (l == "pathtrace") return RenderMode::PathTrace;
  fail("unknown render mode '{}' (expected raymarch, shadow or pathtrace)", s);
}
RenderStrategy parse_render_strategy(const std::string& s) {
  std::string l = to_lower(s);
  if (l == "streaming") return RenderStrategy::Streaming;
  if (l == "inshader") return RenderStrategy::InShader;
  fail("unknown render strategy '{}' (expected streaming or inshader)", s);
}
const char* render_mode_name(RenderMode m) {
  return m == RenderMode::RayMarch ? "raymarch" : (m == RenderMode::Shadow ? "shadow" : "pathtrace");
}
const char* render_strategy_name(RenderStrategy s) { return s == RenderStrategy::InShader ? "inshader" : "streaming"; }

RenderParams make_render_params(Int3 dims, Vec3f box, const MacroCells& mc, const TransferFunction& tf,
                                const Camera& cam, const RenderOptions& opt) {
  if (opt.width < 1 || opt.height < 1 || int64_t(opt.width) * opt.height > (int64_t(1) << 30))
    fail("invalid image size {}x{}", opt.width, opt.height);
  if (!(opt.step > 0) || !std::isfinite(opt.step)) fail("the step must be a positive number (got {})", opt.step);
  if (opt.step_max != 0 && !(opt.step_max >= opt.step))
    fail("the largest step ({}) must not be below the base step ({})", opt.step_max, opt.step);
  if (!(opt.density_scale >= 0) || !std::isfinite(opt.density_scale))
    fail("the density scale must be a non-negative number (got {})", opt.density_scale);
  if (opt.samples_per_iteration < 1 || opt.samples_per_iteration > 1024)
    fail("samples per iteration must be in [1, 1024] (got {})", opt.samples_per_iteration);
  if (tf.table.size() < 2) fail("the transfer function needs at least 2 entries");
  if (!(length(opt.light.direction) > 0)) fail("the light direction must not be zero");
  RenderParams p;
  p.box = box;
  p.inv_box = Vec3f{1 / box.x, 1 / box.y, 1 / box.z};
  p.tf = view_of(tf);
  p.mc = mc.view();
  p.step = opt.step;
  p.step_max = opt.step_max > 0 ? opt.step_max : 16 * opt.step;
  p.shadow_step = 2 * opt.step;
  p.shade = opt.shade;
  // one voxel, in normalised coordinates
  p.grad_h = Vec3f{1.0f / float(dims.x), 1.0f / float(dims.y), 1.0f / float(dims.z)};
  p.light_color = opt.light.color;
  p.background = opt.background;
  p.density_scale = opt.density_scale;
  p.seed = opt.seed;
  set_render_camera(p, cam, opt);
  return p;
}

void set_render_camera(RenderParams& p, const Camera& cam, const RenderOptions& opt) {
  p.cam = make_camera_frame(cam, opt.width, opt.height);
  p.light_dir = normalize(opt.light.direction);
  if (dot(p.light_dir, cam.eye - cam.center) < 0) p.light_dir = -p.light_dir;
}

void FrameRenderer::render_frame_resident(uint32_t frame, RenderStats* stats) { render_frame(frame, resident_, stats); }

Image FrameRenderer::render(int frames, RenderStats* stats) {
  if (frames < 1) fail("the number of frames (samples per pixel) must be at least 1 (got {})", frames);
  Image acc, frame_img;
  for (int f = 0; f < frames; ++f) {
    render_frame(uint32_t(f), frame_img, stats);
    if (f == 0) acc = Image(frame_img.width, frame_img.height);
    accumulate_frame(acc, frame_img, f);
  }
  return acc;
}

CpuRenderer::CpuRenderer(const Field& field, Vec3f box, const MacroCells& mc, const TransferFunction& tf, const Camera& cam,
                   const RenderOptions& opt)
    : field_(field), opt_(opt), params_(make_render_params(field.dims(), box, mc, tf, cam, opt)) {}

void CpuRenderer::set_camera(const Camera& cam) { set_render_camera(params_, cam, opt_); }

template <class PointFn>
void CpuRenderer::inshader(const PointFn& f, Image& img, RenderStats& st) {
  const RenderParams& p = params_;
  const int W = opt_.width, H = opt_.height;
  // 8x8 pixel tiles dealt round-robin to threads: neighbouring rays read neighbouring voxels.
  std::atomic<int64_t> samples{0};
  const RenderMode mode = opt_.mode;
  if constexpr (std::is_same_v<PointFn, GridPointFn>) {
    if (opt_.ray_packets && mode == RenderMode::RayMarch && grid_packets_apply(p, f.g)) {
      parallel_threads([&](int t, int nt) {
        samples += march_grid_packets(p, f.g, TileCursor{W, H, kTile, t, nt}, img.pixels.data());
      });
      st.field_samples += samples.load();
      return;
    }
  }
  parallel_threads([&](int t, int nt) {
    int64_t my_samples = 0;
    TileCursor pixels{W, H, kTile, t, nt};
    for (int ix, iy; pixels.next(&ix, &iy);) {
      const int64_t i = int64_t(iy) * W + ix;
      if (mode == RenderMode::PathTrace) {
        PathState s;
        if (pt_begin(p, ix, iy, s) && pt_sample(p, s)) {
          for (;;) {
            Vec3f u = s.pos * p.inv_box;
            float v = f(u.x, u.y, u.z);
            ++my_samples;
            if (!(pt_shade(p, s, v) && pt_sample(p, s))) break;
          }
        }
        img.pixels[i] = pt_pixel(s);
        continue;
      }
      MarchState s;
      if (!march_begin(p, ix, iy, s)) {
        img.pixels[i] = march_pixel(p, s);
        continue;
      }
      Vec3f pos;
      float dt;
      // M points per sample (1, or 7 with shading); a compile-time M keeps an unshaded sample out of
      // the 7-point arrays (a fifth of a grid sample's instructions otherwise).
      auto march = [&](auto points) {
        constexpr int M = decltype(points)::value;
        while (march_next(p, s, &pos, &dt)) {
          float x[M], y[M], z[M], v[M];
          march_sample_points(p, pos, M, x, y, z);
          for (int k = 0; k < M; ++k) v[k] = f(x[k], y[k], z[k]);
          my_samples += M;
          if (!march_shade(p, s, pos, dt, v, M)) break;
        }
      };
      if (march_points_per_sample(p) == 1) march(std::integral_constant<int, 1>{});
      else march(std::integral_constant<int, 7>{});
      if (mode == RenderMode::Shadow) {
        ShadowState sh;
        if (shadow_begin(p, s, sh)) {
          while (shadow_next(p, sh, &pos, &dt)) {
            Vec3f u = pos * p.inv_box;
            float v = f(u.x, u.y, u.z);
            ++my_samples;
            if (!shadow_shade(p, sh, v, dt)) break;
          }
        }
        img.pixels[i] = shadow_pixel(p, s, sh.T);
      } else {
        img.pixels[i] = march_pixel(p, s);
      }
    }
    samples += my_samples;
  });
  st.field_samples += samples.load();
}

void CpuRenderer::query(int64_t n, RenderStats& st) {
  qv_.resize(size_t(n));
  if (n > 0) field_.query(qx_.data(), qy_.data(), qz_.data(), n, qv_.data());
  st.field_samples += n;
  st.iterations += 1;
}

namespace {
// All pixel indices of a W x H image in 8x8-tile order (the streaming queues start in this order so
// that neighbouring queue entries are neighbouring rays).
void tiled_pixel_order(int W, int H, std::vector<int32_t>& out) {
  out.clear();
  TileCursor pixels{W, H, kTile, 0, 1};
  for (int x, y; pixels.next(&x, &y);) out.push_back(int32_t(y) * W + x);
}
// Keeps the live rays whose keep flag is set, in order.
void compact(std::vector<int32_t>& live, const std::vector<uint8_t>& keep, std::vector<int32_t>& scratch) {
  scratch.clear();
  for (size_t r = 0; r < live.size(); ++r)
    if (keep[r]) scratch.push_back(live[r]);
  live.swap(scratch);
}
// Keeps the pixels (live holds pixel indices) whose keep flag is set.
void compact_pixels(std::vector<int32_t>& live, const std::vector<uint8_t>& keep, std::vector<int32_t>& scratch) {
  scratch.clear();
  for (int32_t i : live)
    if (keep[i]) scratch.push_back(i);
  live.swap(scratch);
}
constexpr int64_t kGrain = 512;  // rays per parallel work item in the streaming stages
}  // namespace

void CpuRenderer::start_queue() {
  tiled_pixel_order(opt_.width, opt_.height, live_);
  compact_pixels(live_, keep_, next_live_);
}

void CpuRenderer::stream_march(Image& img, RenderStats& st) {
  const RenderParams& p = params_;
  const int W = opt_.width;
  const int64_t n = int64_t(W) * opt_.height;
  const int K = opt_.samples_per_iteration;
  const int m = march_points_per_sample(p);
  const bool shadows = opt_.mode == RenderMode::Shadow;
  march_.resize(size_t(n));
  keep_.resize(size_t(n));
  // ray generation
  parallel_for_range(n, 4096, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) keep_[i] = march_begin(p, int(i % W), int(i / W), march_[i]);
  });
  start_queue();

  // The streaming loop shared by primary and shadow rays: next(ray, pos, dt) emits samples,
  // shade(ray, pos, dt, values) consumes them; rays that end are dropped.
  auto stream = [&](int points, auto&& next, auto&& emit, auto&& shade) {
    while (!live_.empty()) {
      const int64_t nl = int64_t(live_.size());
      count_.resize(size_t(nl));
      offset_.resize(size_t(nl) + 1);
      spos_.resize(size_t(nl) * K);
      sdt_.resize(size_t(nl) * K);
      // coordinate stage: up to K samples per live ray
      parallel_for_range(nl, kGrain, [&](int64_t b, int64_t e) {
        for (int64_t r = b; r < e; ++r) {
          int c = 0;
          while (c < K && next(live_[r], &spos_[r * K + c], &sdt_[r * K + c])) ++c;
          count_[r] = c;
        }
      });
      offset_[0] = 0;
      for (int64_t r = 0; r < nl; ++r) offset_[r + 1] = offset_[r] + count_[r];
      const int64_t ns = offset_[nl] * points;
      qx_.resize(size_t(ns));
      qy_.resize(size_t(ns));
      qz_.resize(size_t(ns));
      parallel_for_range(nl, kGrain, [&](int64_t b, int64_t e) {
        for (int64_t r = b; r < e; ++r)
          for (int k = 0; k < count_[r]; ++k) {
            int64_t q = (offset_[r] + k) * points;
            emit(spos_[r * K + k], &qx_[q], &qy_[q], &qz_[q]);
          }
      });
      query(ns, st);  // one batched inference per iteration
      // shading stage
      keep_.resize(size_t(nl));
      parallel_for_range(nl, kGrain, [&](int64_t b, int64_t e) {
        for (int64_t r = b; r < e; ++r) {
          bool alive = count_[r] == K;
          for (int k = 0; k < count_[r]; ++k)
            if (!shade(live_[r], spos_[r * K + k], sdt_[r * K + k], &qv_[(offset_[r] + k) * points])) {
              alive = false;
              break;
            }
          keep_[r] = alive;
        }
      });
      compact(live_, keep_, next_live_);
    }
  };

  stream(
      m, [&](int32_t i, Vec3f* pos, float* dt) { return march_next(p, march_[i], pos, dt); },
      [&](Vec3f pos, float* x, float* y, float* z) { march_sample_points(p, pos, m, x, y, z); },
      [&](int32_t i, Vec3f pos, float dt, const float* v) { return march_shade(p, march_[i], pos, dt, v, m); });

  if (!shadows) {
    parallel_for(n, [&](int64_t i) { img.pixels[i] = march_pixel(p, march_[i]); });
    return;
  }
  // second pass: one shadow ray per pixel from its highest-contribution sample
  shadow_.resize(size_t(n));
  keep_.resize(size_t(n));
  parallel_for_range(n, 4096, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) keep_[i] = shadow_begin(p, march_[i], shadow_[i]);
  });
  start_queue();
  stream(
      1, [&](int32_t i, Vec3f* pos, float* dt) { return shadow_next(p, shadow_[i], pos, dt); },
      [&](Vec3f pos, float* x, float* y, float* z) {
        Vec3f u = pos * p.inv_box;
        *x = u.x, *y = u.y, *z = u.z;
      },
      [&](int32_t i, Vec3f, float dt, const float* v) { return shadow_shade(p, shadow_[i], v[0], dt); });
  parallel_for(n, [&](int64_t i) { img.pixels[i] = shadow_pixel(p, march_[i], shadow_[i].T); });
}

void CpuRenderer::stream_path(Image& img, RenderStats& st) {
  const RenderParams& p = params_;
  const int W = opt_.width;
  const int64_t n = int64_t(W) * opt_.height;
  path_.resize(size_t(n));
  keep_.resize(size_t(n));
  // ray generation absorbs the first sample() (paper: raygen_kernel<PT_RAY>)
  parallel_for_range(n, 4096, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) {
      PathState& s = path_[i];
      keep_[i] = pt_begin(p, int(i % W), int(i / W), s) && pt_sample(p, s);
      if (!keep_[i]) img.pixels[i] = pt_pixel(s);
    }
  });
  start_queue();
  while (!live_.empty()) {
    const int64_t nl = int64_t(live_.size());
    qx_.resize(size_t(nl));
    qy_.resize(size_t(nl));
    qz_.resize(size_t(nl));
    parallel_for_range(nl, kGrain, [&](int64_t b, int64_t e) {
      for (int64_t r = b; r < e; ++r) {
        Vec3f u = path_[live_[r]].pos * p.inv_box;
        qx_[r] = u.x, qy_[r] = u.y, qz_[r] = u.z;
      }
    });
    query(nl, st);
    keep_.resize(size_t(nl));
    parallel_for_range(nl, kGrain, [&](int64_t b, int64_t e) {
      for (int64_t r = b; r < e; ++r) {
        PathState& s = path_[live_[r]];
        keep_[r] = pt_shade(p, s, qv_[r]) && pt_sample(p, s);
        if (!keep_[r]) img.pixels[live_[r]] = pt_pixel(s);
      }
    });
    compact(live_, keep_, next_live_);
  }
}

void CpuRenderer::render_frame(uint32_t frame, Image& img, RenderStats* stats) {
  RenderStats local;
  RenderStats& st = stats ? *stats : local;
  auto t0 = std::chrono::steady_clock::now();
  if (img.width != opt_.width || img.height != opt_.height) img = Image(opt_.width, opt_.height);
  params_.frame = frame;
  if (opt_.strategy == RenderStrategy::Streaming) {
    if (opt_.mode == RenderMode::PathTrace)
      stream_path(img, st);
    else
      stream_march(img, st);
  } else if (auto* g = dynamic_cast<const GridField*>(&field_)) {
    inshader(g->point_fn(), img, st);
  } else if (auto* nf = dynamic_cast<const NetworkField*>(&field_)) {
    inshader(nf->point_fn(), img, st);
  } else {
    fail("the in-shader strategy needs a grid or network field");
  }
  st.frames += 1;
  st.rays += int64_t(opt_.width) * opt_.height;
  st.seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

void accumulate_frame(Image& acc, const Image& frame, int index) {
  const float w = 1.0f / float(index + 1);  // running mean
  parallel_for(int64_t(acc.pixels.size()), [&](int64_t i) {
    Vec4f& a = acc.pixels[i];
    const Vec4f& b = frame.pixels[i];
    a = Vec4f{a.x + (b.x - a.x) * w, a.y + (b.y - a.y) * w, a.z + (b.z - a.z) * w, a.w + (b.w - a.w) * w};
  });
}

}  // namespace vnr
