// ViewerEngine's images: the network and truth views (progressive accumulation, coarse frames while
// interacting), the slice images and the value histogram.
#include <algorithm>
#include <cmath>
#include <utility>
#include "vnr/api/model_field.h"
#include "vnr/api/viewer_impl.h"
#include "vnr/error.h"
#include "vnr/render_cuda/gpu_renderer.h"
#include "vnr/train/decoder.h"

namespace vnr {

namespace {

constexpr int kCellSize = 16;
// The difference slice maps |network - truth| (normalised units) over [0, kDifferenceScale] through
// the "hot" preset's colours (black, red, yellow, white), clamped above.
constexpr float kDifferenceScale = 0.1f;

bool same_vec(Vec3f a, Vec3f b) { return a.x == b.x && a.y == b.y && a.z == b.z; }

}  // namespace

bool same_camera(const Camera& a, const Camera& b) {
  return same_vec(a.eye, b.eye) && same_vec(a.center, b.center) && same_vec(a.up, b.up) && a.fovy == b.fovy;
}

// The RenderOptions `vnr render` would use with these settings (the scene's background and light colour);
// for strategies cache and auto, render() sets each view's strategy.
RenderOptions viewer_render_options(const ViewerRender& r, const Scene& scene, int width, int height) {
  const RenderSettings& s = r.settings;
  RenderOptions o;
  o.mode = parse_render_mode(s.mode);
  o.strategy = s.strategy == "inshader" ? RenderStrategy::InShader : RenderStrategy::Streaming;
  o.width = width;
  o.height = height;
  o.step = s.step;
  o.density_scale = s.density;
  o.shade = s.shade;
  o.background = scene.background.value_or(Vec3f{0, 0, 0});
  o.light = scene.light.value_or(DirectionalLight{});
  o.light.direction = s.light.value_or(viewer_default_light());
  return o;
}

bool viewer_wants_cache(const ViewerRender& r, bool gpu_training) {
  return r.settings.strategy == "cache" || (r.settings.strategy == "auto" && !gpu_training);
}

int viewer_max_frames(const ViewerRender& r) {
  if (r.max_frames > 0) return r.max_frames;
  switch (parse_render_mode(r.settings.mode)) {
    case RenderMode::Shadow: return 16;
    case RenderMode::PathTrace: return 256;
    case RenderMode::RayMarch:
    default: return 8;
  }
}

namespace {

// Renders the next frame of `pass` (restarting it when its content, settings or camera changed, or its
// cache decoded bricks); false when it already holds `target` frames and its cache waits for nothing.
bool render_pass(ViewPass& pass, const ViewContent& content, const TransferFunction& tf, const ViewerSnapshot& snap,
                 const RenderOptions& opt, bool coarse, int target, Device device, Vec3f box) {
  const Camera& cam = snap.state.camera;
  if (!pass.backend || pass.content_version != content.version || pass.tf_epoch != snap.tf_epoch ||
      pass.options_epoch != snap.options_epoch || pass.coarse != coarse) {
    pass.backend.reset();
    pass.backend = make_renderer(device, content.drawn(), box, *content.mc, tf, cam, opt, cuda::MlpPath::Auto);
    // The host field holds the parameters of the last download; a GPU trainer's latest are on the device.
    if (content.device_half) pass.backend->refresh_network(*content.mc, content.device_half);
    pass.content_version = content.version;
    pass.params_version = content.params_version;
    pass.tf_epoch = snap.tf_epoch;
    pass.options_epoch = snap.options_epoch;
    pass.coarse = coarse;
    pass.camera = cam;
    pass.count = 0;
  } else if (pass.params_version != content.params_version) {
    // Training changed the network's parameters and ranges only: taken in place (GPU), else a new backend.
    if (!pass.backend->refresh_network(*content.mc, content.device_half)) {
      pass.backend.reset();  // its GPU buffers go before the new renderer's are made
      pass.backend = make_renderer(device, content.drawn(), box, *content.mc, tf, cam, opt, cuda::MlpPath::Auto);
    }
    pass.params_version = content.params_version;
    pass.count = 0;
  }
  if (!same_camera(pass.camera, cam)) {
    pass.backend->set_camera(cam);
    pass.camera = cam;
    pass.count = 0;
  }
  if (content.cache && pass.cache_version != content.cache->content_version()) {
    pass.cache_version = content.cache->content_version();  // bricks came in: the image sharpens
    pass.count = 0;
  }
  if (pass.count >= target) {
    if (!content.cache) return false;
    const BrickCacheStats cs = content.cache->stats();
    if (cs.requested == 0 && cs.stale == 0) return false;
    // A frame more decodes (or refreshes) the bricks the view still waits for; with a decoding thread,
    // once it has finished one (or soon: the requests of the next frame go to it).
    content.cache->wait_for_bricks(0.05);
    pass.count = 0;
  }
  pass.backend->render_mean_rgba8(uint32_t(pass.count), pass.rgba);
  pass.width = opt.width;
  pass.height = opt.height;
  ++pass.count;
  return true;
}

ViewerImage gray_image(const char* view, int w, int h, const std::vector<float>& values) {
  ViewerImage img{view, w, h, std::vector<uint8_t>(values.size() * 4)};
  for (size_t i = 0; i < values.size(); ++i) {
    img.rgba[4 * i] = img.rgba[4 * i + 1] = img.rgba[4 * i + 2] = channel_to_u8(values[i]);
    img.rgba[4 * i + 3] = 255;
  }
  return img;
}

ViewerImage difference_image(int w, int h, const std::vector<float>& net, const std::vector<float>& truth) {
  static const TransferFunction hot = tf_preset("hot");
  const TfView colours = view_of(hot);
  ViewerImage img{"slice_difference", w, h, std::vector<uint8_t>(net.size() * 4)};
  for (size_t i = 0; i < net.size(); ++i) {
    const Vec4f c = tf_lookup(colours, std::fabs(net[i] - truth[i]) / kDifferenceScale);
    img.rgba[4 * i + 0] = channel_to_u8(c.x);
    img.rgba[4 * i + 1] = channel_to_u8(c.y);
    img.rgba[4 * i + 2] = channel_to_u8(c.z);
    img.rgba[4 * i + 3] = 255;
  }
  return img;
}

}  // namespace

// The voxels of the slice plane, row 0 at the top: axis 2 (z) shows x to the right and y up, axis 1
// (y) x right and z up, axis 0 (x) y right and z up.
static std::vector<int64_t> slice_voxels(Int3 d, int axis, int index, int* width, int* height) {
  const int64_t n[3] = {d.x, d.y, d.z};
  const int u = axis == 0 ? 1 : 0, v = axis == 2 ? 1 : 2;
  *width = int(n[u]);
  *height = int(n[v]);
  std::vector<int64_t> out(size_t(n[u] * n[v]));
  for (int64_t row = 0; row < n[v]; ++row)
    for (int64_t col = 0; col < n[u]; ++col) {
      int64_t p[3];
      p[axis] = index;
      p[u] = col;
      p[v] = n[v] - 1 - row;
      out[size_t(row * n[u] + col)] = p[0] + d.x * (p[1] + d.y * p[2]);
    }
  return out;
}

// The grid macro-cells' value ranges of the current volume (computed once per timestep).
const ValueRangeGrid& ViewerEngine::Impl::volume_ranges() {
  if (grid_ranges_version != volume_version) {
    grid_ranges = render_device == Device::Cuda ? gpu_value_ranges_from_grid(view_of(*volume), kCellSize)
                                                : value_ranges_from_grid(view_of(*volume), kCellSize);
    grid_ranges_version = volume_version;
  }
  return *grid_ranges;
}

// The network's field (behind its brick cache when `cache`) and macro-cells for the current parameters
// and macro-cell mode. Training keeps a cache: its bricks turn stale and are decoded again a few a frame.
void ViewerEngine::Impl::update_network_content(MacroCellMode mode, bool cache) {
  ViewContent& c = net_content;
  if (c.field && c.params_version == model_version && c.mode == mode && bool(c.cache) == cache) return;
  // Training on the GPU changed only the parameters: they are taken in place from the trainer's device
  // copy -- by the renderer's network (render_pass), or behind the brick cache by the cache's decoder, the
  // cache's bricks turning stale -- instead of a download, a host fp16 copy and a new GPU network every
  // chunk. The renderer keeps its buffers (and its copy of the cache) and takes the new ranges.
  if (c.field && c.mode == mode && bool(c.cache) == cache && render_device == Device::Cuda && run.session) {
    const void* half = run.session->trainer().device_half_params();
    if (c.cache ? c.decoder->reload_device_params(half) : half != nullptr) {
      if (c.cache) c.cache->replace_source(*c.field, true);
      c.mc = network_macrocells(mode);
      c.mc->update(tf);
      c.device_half = half;
      c.params_version = model_version;
      return;
    }
  }
  const bool params_changed = c.version != model_version;
  net_pass.backend.reset();  // it refers to the old field and cells
  if (run.session) run.session->trainer().download();
  std::unique_ptr<RenderableField> old = std::move(c.field);  // the cache reads it until it has the new one
  // Behind a cache the field is the host cache's source alone (kCacheSourceDevice).
  c.field = make_model_field(*model, cache ? kCacheSourceDevice : render_device);
  if (!cache) {
    c.cache.reset();
    c.decoder.reset();
  } else if (!c.cache) {
    BrickCacheSettings s;
    s.misses = CacheMisses::Coarser;  // frames never wait for the network: coarser levels until bricks come in
    s.budget_bytes = setup.cache_budget;
    s.dims = setup.cache_dims;
    s = cache_settings_for(s, render_device);
    c.decoder = std::make_shared<Decoder>(*model, render_device);
    c.cache = make_model_cache(*model, *c.field, s, c.decoder);
  } else {
    // A GPU decoder copied the parameters it decodes with: one of the new parameters (the CPU's reads them).
    const bool new_decoder = params_changed && render_device == Device::Cuda;
    if (new_decoder) c.decoder = std::make_shared<Decoder>(*model, render_device);
    c.cache->replace_source(*c.field, params_changed, new_decoder ? cache_decode(c.decoder) : VoxelDecode{});
  }
  c.mc = network_macrocells(mode);
  c.version = model_version;
  c.params_version = model_version;
  c.device_half = nullptr;
  c.mode = mode;
  c.tf_epoch = ~uint64_t(0);
}

// The network view's macro-cells in `mode` for the current parameters.
std::unique_ptr<MacroCells> ViewerEngine::Impl::network_macrocells(MacroCellMode mode) {
  const bool trained = run.session && run.session->steps_done() > 0;
  if (mode == MacroCellMode::Online && trained)
    return std::make_unique<MacroCells>(run.session->trainer().online_ranges(), box);
  if (mode == MacroCellMode::Online && model->macrocells) return std::make_unique<MacroCells>(*model->macrocells, box);
  if (mode == MacroCellMode::Grid && volume) return std::make_unique<MacroCells>(volume_ranges(), box);
  // off, or online before the first step (no samples yet: the untrained network shows as it is)
  return std::make_unique<MacroCells>(MacroCells::single(model->dims, box));
}

// The truth volume's field and grid macro-cells for the current timestep.
void ViewerEngine::Impl::update_truth_content() {
  ViewContent& c = truth_content;
  if (c.field && c.version == volume_version) return;
  truth_pass.backend.reset();
  c.field = std::make_unique<GridField>(view_of(*volume));
  c.mc = std::make_unique<MacroCells>(volume_ranges(), box);
  c.version = volume_version;
  c.mode = MacroCellMode::Grid;
  c.tf_epoch = ~uint64_t(0);
}

// The network view's cache for this frame: while the camera moves, decoded by the cache's own thread
// (one core) so frames come at their rate; while the view is still, by each frame for 0.1 s on every
// core (on few cores the fastest way to a sharp image), and for 10 ms while training in the loop (the
// model changes between frames; training gets 1.4x a frame's render time); and the ray under the
// cursor, whose bricks come first.
static void steer_cache(const CachedField& cache, const ViewerSnapshot& snap, const RenderOptions& opt) {
  const bool training = snap.state.training.state == TrainingState::Running;
  cache.set_decode_seconds(training ? 0.01 : 0.1);
  cache.set_asynchronous(!training && snap.interacting);
  std::optional<std::pair<Vec3f, Vec3f>> focus;
  if (snap.cursor) {
    const CameraFrame f = make_camera_frame(snap.state.camera, opt.width, opt.height);
    const float x = (*snap.cursor)[0] * float(f.width), y = (*snap.cursor)[1] * float(f.height);
    focus = std::make_pair(f.eye, camera_ray_dir(f, 0, 0, x, y));
  }
  cache.set_focus(focus);
}

// Renders one frame of each view the layout needs that is not complete, and the slices when on.
bool ViewerEngine::Impl::render(const ViewerSnapshot& snap, bool* refined, int* accumulated) {
  const ViewerState& st = snap.state;
  if (built_tf_epoch != snap.tf_epoch) {
    // Backends point into tf: every one is rebuilt for the new epoch before it renders again.
    tf = to_transfer_function(st.tf);
    built_tf_epoch = snap.tf_epoch;
  }
  const bool gpu = render_device == Device::Cuda;
  const bool gpu_training = gpu && train_device == Device::Cuda && st.training.state == TrainingState::Running;
  const bool want_cache = viewer_wants_cache(st.render, gpu_training) && st.view.layout != ViewLayout::Truth;
  // Coarse frames while the camera moves on the CPU alone: the cache renders full frames then, and on the
  // GPU a full frame takes a few ms (a coarse one would rebuild the renderer at each drag's start and end).
  const bool coarse = snap.interacting && !want_cache && !gpu;
  const int scale = coarse ? st.render.coarse_scale : 1;
  const RenderOptions opt =
      viewer_render_options(st.render, input.scene, std::max(1, st.width / scale), std::max(1, st.height / scale));
  RenderOptions net_opt = opt, truth_opt = opt;
  if (want_cache) {
    net_opt.strategy = fastest_render_strategy("cache", gpu, opt.mode);
  } else if (st.render.settings.strategy == "auto") {
    net_opt.strategy = automatic_strategy_for(model, "network", render_device, opt.mode);
  }
  // What the cache does not draw: on the GPU the grid in-shader (16x streaming's frames/s, docs/benchmarks.md
  // "CUDA backend"); on the CPU streaming, as vnr::Renderer's default.
  if (gpu && (st.render.settings.strategy == "cache" || st.render.settings.strategy == "auto"))
    truth_opt.strategy = fastest_render_strategy("grid", gpu, opt.mode);
  const int target = coarse ? 1 : viewer_max_frames(st.render);
  const bool want_net = st.view.layout != ViewLayout::Truth;
  const bool want_truth = volume && st.view.layout != ViewLayout::Network;
  auto draw = [&](ViewContent& c, ViewPass& pass, const RenderOptions& o) {
    if (c.tf_epoch != snap.tf_epoch) {
      pass.backend.reset();
      c.mc->update(tf);
      c.tf_epoch = snap.tf_epoch;
    }
    return render_pass(pass, c, tf, snap, o, coarse, target, render_device, box);
  };
  bool any = false;
  if (want_net) {
    update_network_content(parse_macrocell_mode(st.render.settings.macrocells), want_cache);
    if (net_content.cache) steer_cache(*net_content.cache, snap, net_opt);
    any |= draw(net_content, net_pass, net_opt);
  }
  if (want_truth) {
    update_truth_content();
    any |= draw(truth_content, truth_pass, truth_opt);
  }
  *refined = !coarse;
  *accumulated = (want_net ? net_pass : truth_pass).count;
  if (st.view.slice) any |= render_slices(st.view);
  return any;
}

// The slice images (truth, network, difference) of the plane the view selects, when it changed.
bool ViewerEngine::Impl::render_slices(const ViewSettings& view) {
  const Int3 d = model->dims;
  const int64_t n = view.slice_axis == 0 ? d.x : (view.slice_axis == 1 ? d.y : d.z);
  const int index = int(std::clamp<int64_t>(int64_t(view.slice_position * float(n)), 0, n - 1));
  SliceCache& sc = slices;
  if (sc.axis == view.slice_axis && sc.index == index && sc.model_version == model_version &&
      sc.volume_version == volume_version)
    return false;
  int w = 0, h = 0;
  const std::vector<int64_t> voxels = slice_voxels(d, view.slice_axis, index, &w, &h);
  std::vector<float> net(voxels.size()), truth;
  current_decoder(sc.decoder, render_device).voxels(d, voxels.data(), int64_t(voxels.size()), net.data());
  sc.images.clear();
  if (volume) {
    truth.resize(voxels.size());
    for (size_t i = 0; i < voxels.size(); ++i) truth[i] = volume->data[size_t(voxels[i])];
    sc.images.push_back(gray_image("slice_truth", w, h, truth));
  }
  sc.images.push_back(gray_image("slice_network", w, h, net));
  if (volume) sc.images.push_back(difference_image(w, h, net, truth));
  sc.axis = view.slice_axis;
  sc.index = index;
  sc.model_version = model_version;
  sc.volume_version = volume_version;
  return true;
}

// The images of a frame in the layout's order: network, truth, then the slices.
std::vector<ViewerImage> ViewerEngine::Impl::frame_images(const ViewerSnapshot& snap) const {
  const ViewerState& st = snap.state;
  std::vector<ViewerImage> out;
  auto add = [&](const char* name, const ViewPass& p) {
    if (p.count > 0) out.push_back(ViewerImage{name, p.width, p.height, p.rgba});
  };
  if (st.view.layout != ViewLayout::Truth) add("network", net_pass);
  if (volume && st.view.layout != ViewLayout::Network) add("truth", truth_pass);
  if (st.view.slice)
    for (const ViewerImage& img : slices.images) out.push_back(img);
  return out;
}

// Counts of the normalised values in kFineBins bins: the truth volume's, else the network decoded on
// a grid of at most 64 voxels per axis.
void ViewerEngine::Impl::compute_histogram() {
  std::vector<uint64_t> counts(size_t(kFineBins), 0);
  auto count = [&](const float* v, size_t n) {
    for (size_t i = 0; i < n; ++i) {
      const float u = std::clamp(v[i], 0.0f, 1.0f);
      ++counts[std::min<size_t>(size_t(u * float(kFineBins)), size_t(kFineBins - 1))];
    }
  };
  if (volume) {
    count(volume->data.data(), volume->data.size());
  } else {
    const Int3 d{std::min<int64_t>(model->dims.x, 64), std::min<int64_t>(model->dims.y, 64),
                 std::min<int64_t>(model->dims.z, 64)};
    std::vector<float> values(d.count());
    Decoder(*model->net, render_device).slices(d, 0, d.z, values.data());
    count(values.data(), values.size());
  }
  std::lock_guard<std::mutex> lock(mu);
  fine_histogram = std::move(counts);
}

}  // namespace vnr
