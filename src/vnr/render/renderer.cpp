#include "vnr/render/renderer.h"
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <utility>
#include "vnr/error.h"
#include "vnr/json.h"
#include "vnr/core/parallel.h"
#include "vnr/render/field.h"
#include "vnr/render/inshader.h"
#include "vnr/render/stream_driver.h"
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

RenderStrategy fastest_render_strategy(const std::string& field_kind, bool gpu, RenderMode mode) {
  const bool grid = field_kind == "grid" || field_kind == "cache";  // the cache is a grid of bricks
  if (gpu) return grid || mode != RenderMode::Shadow ? RenderStrategy::InShader : RenderStrategy::Streaming;
  return grid && mode != RenderMode::Shadow ? RenderStrategy::InShader : RenderStrategy::Streaming;
}

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

void FrameRenderer::render_mean_rgba8(uint32_t frame, std::vector<uint8_t>& rgba) {
  render_frame(frame, frame_);
  if (frame == 0 || mean_.pixels.size() != frame_.pixels.size())  // (a mean not started: this frame starts it)
    std::swap(mean_, frame_);  // a frame overwrites its image: no copy
  else
    accumulate_frame(mean_, frame_, int(frame));
  rgba = to_rgba8(mean_);
}

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

namespace {
// All pixel indices of a W x H image in 8x8-tile order (the streaming queues start in this order so
// that neighbouring queue entries are neighbouring rays).
void tiled_pixel_order(int W, int H, std::vector<int32_t>& out) {
  out.clear();
  TileCursor pixels{W, H, kInshaderTile, 0, 1};
  for (int x, y; pixels.next(&x, &y);) out.push_back(int32_t(y) * W + x);
}
constexpr int64_t kGrain = 512;  // pixels or queue slots per parallel work item
}  // namespace

// The CPU backend of the streaming driver (stream_driver.h): host vectors, stages run by
// parallel_for_range, a sequential scan and compaction, the Field's batched query.
struct CpuStreamBackend {
  CpuStreamBackend(const Field& f, int w, int h) : field(f), width(w), height(h) {}
  const Field& field;
  int width, height;
  std::vector<MarchState> march_;
  std::vector<ShadowState> shadow_;
  std::vector<PathState> path_;
  std::vector<int32_t> live_, next_live_;
  int n_live_ = 0;
  std::vector<uint8_t> keep_;
  std::vector<int64_t> count_, offset_;
  std::vector<Vec3f> spos_;
  std::vector<float> sdt_;
  std::vector<float> qx_, qy_, qz_, qv_;

  template <class Stage>
  void run(int64_t n, const Stage& stage) {
    parallel_for_claimed(n, kGrain, [&](int64_t b, int64_t e) {
      for (int64_t r = b; r < e; ++r) stage(r);
    });
  }
  MarchState* march_states(int64_t n) { return resized(march_, n); }
  ShadowState* shadow_states(int64_t n) { return resized(shadow_, n); }
  PathState* path_states(int64_t n) { return resized(path_, n); }
  uint8_t* pixel_keep(int64_t n) { return resized(keep_, n); }
  // live = the keep-flagged pixels in 8x8-tile order
  int64_t start_queue() {
    tiled_pixel_order(width, height, next_live_);
    live_.clear();
    for (int32_t i : next_live_)
      if (keep_[i]) live_.push_back(i);
    n_live_ = int(live_.size());
    return n_live_;
  }
  int64_t live_count(RenderStats&) const { return n_live_; }
  int32_t* live() { return live_.data(); }
  const int* n_live() const { return &n_live_; }
  uint8_t* keep() { return keep_.data(); }
  void slots(int64_t cap, int K) {
    count_.resize(size_t(cap) + 1);
    offset_.resize(size_t(cap) + 1);
    spos_.resize(size_t(cap) * K);
    sdt_.resize(size_t(cap) * K);
  }
  Vec3f* spos() { return spos_.data(); }
  float* sdt() { return sdt_.data(); }
  int64_t* count() { return count_.data(); }
  int64_t* offset() { return offset_.data(); }
  int64_t scan(int64_t cap, int64_t* total, RenderStats&) {
    offset_[0] = 0;
    for (int64_t r = 0; r < cap; ++r) offset_[r + 1] = offset_[r] + count_[r];
    *total = offset_[cap];
    return n_live_;
  }
  PointSink points(int64_t n) { return PointSink{resized(qx_, n), resized(qy_, n), resized(qz_, n), 1}; }
  const float* query(int64_t n, int* stride, RenderStats&) {
    qv_.resize(size_t(n));
    if (n > 0) field.query(qx_.data(), qy_.data(), qz_.data(), n, qv_.data());
    *stride = 1;
    return qv_.data();
  }
  int64_t compact(int64_t n) {
    next_live_.clear();
    for (int64_t r = 0; r < n; ++r)
      if (keep_[r]) next_live_.push_back(live_[r]);
    live_.swap(next_live_);
    n_live_ = int(live_.size());
    return n_live_;
  }

private:
  template <class T>
  static T* resized(std::vector<T>& v, int64_t n) {
    v.resize(size_t(n));
    return v.data();
  }
};

CpuRenderer::CpuRenderer(const Field& field, Vec3f box, const MacroCells& mc, const TransferFunction& tf,
                         const Camera& cam, const RenderOptions& opt)
    : field_(field),
      opt_(opt),
      params_(make_render_params(field.dims(), box, mc, tf, cam, opt)),
      stream_(std::make_unique<CpuStreamBackend>(field, opt.width, opt.height)) {}
CpuRenderer::~CpuRenderer() = default;

void CpuRenderer::set_camera(const Camera& cam) { set_render_camera(params_, cam, opt_); }

void CpuRenderer::render_frame(uint32_t frame, Image& img, RenderStats* stats) {
  RenderStats local;
  RenderStats& st = stats ? *stats : local;
  auto t0 = std::chrono::steady_clock::now();
  if (img.width != opt_.width || img.height != opt_.height) img = Image(opt_.width, opt_.height);
  params_.frame = frame;
  field_.begin_frame(params_);
  if (opt_.strategy == RenderStrategy::Streaming) {
    if (opt_.mode == RenderMode::PathTrace)
      stream_path_frame(*stream_, params_, img.pixels.data(), st);
    else
      stream_march_frame(*stream_, params_, opt_.mode == RenderMode::Shadow, opt_.samples_per_iteration,
                         img.pixels.data(), st);
  } else {
    st.field_samples += field_.render_inshader(InshaderJob{&params_, opt_.mode, opt_.ray_packets, img.pixels.data()});
  }
  st.frames += 1;
  st.rays += int64_t(opt_.width) * opt_.height;
  st.seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

void accumulate_frame(Image& acc, const Image& frame, int index, std::vector<float>* m2) {
  const float w = 1.0f / float(index + 1);  // running mean
  if (m2 && index == 0) m2->assign(acc.pixels.size(), 0.0f);
  float* m2p = m2 ? m2->data() : nullptr;
  parallel_for(int64_t(acc.pixels.size()), [&](int64_t i) {
    Vec4f& a = acc.pixels[i];
    const Vec4f& b = frame.pixels[i];
    const float old = m2p ? (a.x + a.y + a.z) * (1.0f / 3) : 0.0f;
    a = running_mean(a, b, w);
    if (m2p && index > 0) {
      const float x = (b.x + b.y + b.z) * (1.0f / 3), mean = (a.x + a.y + a.z) * (1.0f / 3);
      m2p[i] += (x - old) * (x - mean);
    }
  });
}

double accumulated_noise(const std::vector<float>& m2, int frames) {
  if (frames < 2 || m2.empty()) return std::numeric_limits<double>::infinity();
  double sum = 0;
  for (float v : m2) sum += double(v);
  return std::sqrt(sum / double(m2.size()) / (double(frames) * double(frames - 1)));
}

}  // namespace vnr
