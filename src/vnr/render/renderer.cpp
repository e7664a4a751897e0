#include "vnr/render/renderer.h"
#include <atomic>
#include <chrono>
#include "vnr/core/error.h"
#include "vnr/core/json.h"
#include "vnr/core/parallel.h"
#include "vnr/render/field.h"
#include "vnr/render/inshader.h"
#include "vnr/render/stream_stages.h"
#include "vnr/render/tiles.h"

namespace vnr {

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
  TileCursor pixels{W, H, kInshaderTile, 0, 1};
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

namespace {
// Runs a per-slot stage (stream_stages.h) over slots [0, n), `grain` slots per parallel work item.
template <class Stage>
void run_stage(int64_t n, int64_t grain, const Stage& stage) {
  parallel_for_range(n, grain, [&](int64_t b, int64_t e) {
    for (int64_t r = b; r < e; ++r) stage(r);
  });
}
}  // namespace

template <class Ops>
void CpuRenderer::stream_pass(const Ops& ops, RenderStats& st) {
  const RenderParams& p = params_;
  const int K = opt_.samples_per_iteration;
  start_queue();
  while (!live_.empty()) {
    const int64_t nl = int64_t(live_.size());
    const int n_live = int(nl);
    count_.resize(size_t(nl));
    offset_.resize(size_t(nl) + 1);
    spos_.resize(size_t(nl) * K);
    sdt_.resize(size_t(nl) * K);
    run_stage(nl, kGrain, StreamNext<Ops>{p, ops, live_.data(), &n_live, K, spos_.data(), sdt_.data(), count_.data()});
    offset_[0] = 0;
    for (int64_t r = 0; r < nl; ++r) offset_[r + 1] = offset_[r] + count_[r];
    const int64_t ns = offset_[nl] * ops.m;
    qx_.resize(size_t(ns));
    qy_.resize(size_t(ns));
    qz_.resize(size_t(ns));
    run_stage(nl, kGrain,
              StreamEmit<Ops>{p, ops, K, spos_.data(), count_.data(), offset_.data(),
                              PointSink{qx_.data(), qy_.data(), qz_.data(), 1}});
    query(ns, st);  // one batched inference per iteration
    keep_.resize(size_t(nl));
    run_stage(nl, kGrain,
              StreamShade<Ops>{p, ops, live_.data(), K, spos_.data(), sdt_.data(), count_.data(), offset_.data(),
                               qv_.data(), 1, keep_.data()});
    compact(live_, keep_, next_live_);
  }
}

void CpuRenderer::stream_march(Image& img, RenderStats& st) {
  const RenderParams& p = params_;
  const int64_t n = int64_t(opt_.width) * opt_.height;
  const bool shadows = opt_.mode == RenderMode::Shadow;
  march_.resize(size_t(n));
  keep_.resize(size_t(n));
  run_stage(n, 4096, MarchBeginStage{p, march_.data(), keep_.data()});
  stream_pass(MarchOps{march_.data(), march_points_per_sample(p)}, st);
  if (shadows) {  // second pass: one shadow ray per pixel from its highest-contribution sample
    shadow_.resize(size_t(n));
    keep_.resize(size_t(n));
    run_stage(n, 4096, ShadowBeginStage{p, march_.data(), shadow_.data(), keep_.data()});
    stream_pass(ShadowOps{shadow_.data()}, st);
  }
  run_stage(n, 4096, MarchPixelStage{p, march_.data(), shadows ? shadow_.data() : nullptr, img.pixels.data()});
}

void CpuRenderer::stream_path(Image& img, RenderStats& st) {
  const RenderParams& p = params_;
  const int64_t n = int64_t(opt_.width) * opt_.height;
  path_.resize(size_t(n));
  keep_.resize(size_t(n));
  run_stage(n, 4096, PathBeginStage{p, path_.data(), keep_.data(), img.pixels.data()});
  start_queue();
  while (!live_.empty()) {
    const int64_t nl = int64_t(live_.size());
    qx_.resize(size_t(nl));
    qy_.resize(size_t(nl));
    qz_.resize(size_t(nl));
    run_stage(nl, kGrain, PathCoords{p, path_.data(), live_.data(), nl, PointSink{qx_.data(), qy_.data(), qz_.data(), 1}});
    query(nl, st);
    keep_.resize(size_t(nl));
    run_stage(nl, kGrain, PathShade{p, path_.data(), live_.data(), qv_.data(), 1, keep_.data(), img.pixels.data()});
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
  } else {
    st.field_samples += field_.render_inshader(InshaderJob{&params_, opt_.mode, opt_.ray_packets, img.pixels.data()});
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
