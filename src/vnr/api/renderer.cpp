// vnr::Renderer: the field, macro-cells and settings behind one object; the backend (CpuRenderer or
// GpuRenderer) is rebuilt lazily after a change, and only a new camera is handed to the live backend.
#include "vnr/renderer.h"
#include <chrono>
#include <cstring>
#include <fstream>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/json.h"
#include "vnr/progress.h"
#include "vnr/core/rng.h"
#include "vnr/fields/brick_cache.h"
#include "vnr/fields/fields.h"
#include "vnr/render/macrocell.h"
#include "vnr/render/renderer.h"
#include "vnr/api/model_field.h"
#include "vnr/render_cuda/gpu_renderer.h"

namespace vnr {

bool is_model_path(const std::string& path) {
  if (is_bricked_model_dir(path)) return true;  // a multi-brick model (train/bricks.h)
  std::ifstream f(path, std::ios::binary);
  if (!f && path.find(':') != std::string::npos) return false;  // FILE.h5:/DATASET, FILE.nc:VAR: open_volume's
  if (!f) fail("cannot open '{}'", path);
  char head[8] = {};
  f.read(head, 8);
  const std::streamsize got = f.gcount();
  if (got >= 8 && std::memcmp(head, "VNRMODEL", 8) == 0) return true;
  const std::string e = extension_of(path);
  if (e == ".vnr") return true;  // read_model reports what is wrong with it
  if (e == ".bson") return true;
  if (e == ".json") {
    // instantvnr's params.json is BSON (binary, starts with its int32 length); scenes and sidecars are text.
    for (std::streamsize i = 0; i < got; ++i) {
      unsigned char c = static_cast<unsigned char>(head[i]);
      if (c == ' ' || c == '\t' || c == '\n' || c == '\r') continue;
      return !(c == '{' || c == '/');
    }
  }
  return false;
}

RenderInput open_render_input(const std::string& input, const std::string& ground_truth,
                              const VolumeOpenOptions& volume_options, Precision precision) {
  RenderInput s;
  if (is_model_path(input)) {
    s.model = load_model(input);
    const Int3 dims = s.model->dims;
    if (dims.count() == 0) fail("'{}' does not say which volume size it represents", input);
    s.model->net->set_inference_precision(precision);
    s.description = "model " + basename_of(input);
    if (!ground_truth.empty()) {
      s.volume = open_volume(ground_truth, volume_options);
      if (!(s.volume->dims == dims))
        fail("the model represents {}x{}x{} voxels but '{}' has {}x{}x{}", dims.x, dims.y, dims.z, ground_truth,
             s.volume->dims.x, s.volume->dims.y, s.volume->dims.z);
    }
  } else {
    if (!ground_truth.empty()) fail("--volume is only for model inputs (the input '{}' is a volume)", input);
    s.volume = open_volume(input, volume_options);
    s.description = "volume " + basename_of(input);
    // An instantvnr scene given as the volume also brings its camera and transfer function.
    if (extension_of(input) == ".json" && parse_json_file(input).contains("dataSource")) s.scene = load_scene(input);
  }
  return s;
}

Device choose_render_device(const std::string& name, const Model* model, std::string* note) {
  const Device asked = cuda::resolve_device(name);
  if (asked == Device::Cpu) return Device::Cpu;
  const std::string why_not =
      model ? gpu_render_reason(*model) : "";
  if (why_not.empty()) return Device::Cuda;
  if (name == "cuda") fail("{}; use --device cpu", why_not);
  if (note) *note = "rendering on the CPU: " + why_not;
  return Device::Cpu;
}

MacroCellMode default_macrocell_mode(const Model* model, const Volume* volume) {
  if (model && model->macrocells) return MacroCellMode::Online;
  if (volume) return MacroCellMode::Grid;
  return MacroCellMode::Off;
}

Renderer::Renderer(const Model* model, const Volume* volume, Device device)
    : model_(model), volume_(volume), device_(device) {
  if (!model && !volume) fail("the render input holds neither a model nor a volume");
  Int3 dims;
  if (model) {
    if (!model->net) fail("the model has no network");
    dims = model->dims;
    if (dims.count() == 0) fail("the model does not say which volume size it represents");
    if (volume && !(volume->dims == dims))
      fail("the model represents {}x{}x{} voxels but its ground-truth volume has {}x{}x{}", dims.x, dims.y, dims.z,
           volume->dims.x, volume->dims.y, volume->dims.z);
  } else {
    dims = volume->dims;
    field_ = std::make_unique<GridField>(view_of(*volume));
  }
  box_ = Vec3f{float(dims.x), float(dims.y), float(dims.z)};
  set_scene(Scene{});
  mc_mode_ = default_macrocell_mode(model, volume);
}

Renderer::Renderer(const Model& model, Device device, const Volume* ground_truth)
    : Renderer(&model, ground_truth, device) {}
Renderer::Renderer(const Volume& volume, Device device) : Renderer(nullptr, &volume, device) {}
Renderer::Renderer(const RenderInput& input, Device device)
    : Renderer(input.model ? &*input.model : nullptr, input.volume ? &*input.volume : nullptr, device) {
  set_scene(input.scene);
}
Renderer::~Renderer() = default;

const char* Renderer::field_kind() const { return field().kind(); }

RenderStrategy Renderer::automatic_strategy() const {
  return automatic_strategy_for(model_, field_kind(), device_, options_.mode);
}

bool Renderer::can_render_inshader() const {
  return !model_ || std::string(field_kind()) != "network" || inshader_can_draw(*model_, device_);
}

double Renderer::noise() const { return accumulated_noise(m2_, frames_); }

void Renderer::invalidate() {
  backend_.reset();
  restart();
}

const RenderableField& Renderer::field() const {
  if (brick_cache_) return *brick_cache_;
  return source_field();
}

const RenderableField& Renderer::source_field() const {
  if (!field_) field_ = make_model_field(*model_, device_);
  return *field_;
}

void Renderer::set_cache(std::optional<BrickCacheSettings> settings) {
  backend_.reset();  // its copy of the cache goes first
  brick_cache_.reset();
  cache_source_.reset();
  cache_settings_ = settings;
  if (settings) {
    if (!model_) fail("the brick cache is for models: a volume is drawn directly");
    // On the GPU: its copy of the cache, decoded there (cache_settings_for), behind it the model's CPU field.
    const BrickCacheSettings s = cache_settings_for(*settings, device_);
    if (device_ != kCacheSourceDevice) cache_source_ = make_model_field(*model_, kCacheSourceDevice);
    brick_cache_ = make_model_cache(*model_, cache_source_ ? *cache_source_ : source_field(), s,
                                    std::make_shared<Decoder>(*model_, device_));
  }
  invalidate();
}

void Renderer::choose_strategy(const std::string& choice, uint64_t cache_budget, Int3 cache_dims, int frames) {
  const std::string c = to_lower(choice);
  if (c != "auto" && c != "cache" && c != "streaming" && c != "inshader")
    fail("unknown render strategy '{}' (expected auto, cache, streaming or inshader)", choice);
  if (c != "auto" && c != "cache") {
    set_cache(std::nullopt);
    return set_strategy(parse_render_strategy(c));
  }
  BrickCacheSettings cache;
  cache.budget_bytes = cache_budget;
  cache.dims = cache_dims;
  const bool pays = frames == 0 || frames >= kCacheFrames || cache_dims.count() > 0;
  if (c == "cache" || (pays && model_)) set_cache(cache);
  else set_cache(std::nullopt);
  set_strategy(automatic_strategy());
}

void Renderer::warm_cache(const std::function<void(int64_t, int64_t)>& progress) {
  if (!brick_cache_) return;
  backend().render_frame(0, frame_);
  brick_cache_->decode_pending(progress);
}

BrickCacheStats Renderer::cache_stats() const { return brick_cache_ ? brick_cache_->stats() : BrickCacheStats{}; }

void Renderer::set_camera(const Camera& camera) {
  camera_ = camera;
  restart();
  if (backend_) backend_->set_camera(camera_);  // the backends update the view in place
}
void Renderer::set_transfer_function(const TransferFunction& tf) {
  tf_ = tf;
  mc_tf_current_ = false;
  invalidate();
}
void Renderer::set_transfer_function(const std::string& preset_or_file) {
  set_transfer_function(load_transfer_function(preset_or_file));
}
void Renderer::set_scene(const Scene& scene) {
  set_camera(camera_for(CameraRequest{}, box_, scene.camera));
  set_transfer_function(scene.tf ? *scene.tf : tf_preset("ramp"));
  options_.light = scene.light ? *scene.light : DirectionalLight{};
  options_.background = scene.background ? *scene.background : Vec3f{0, 0, 0};
  invalidate();
}
void Renderer::set_scene(const std::string& scene_file) { set_scene(load_scene(scene_file)); }
void Renderer::set_mode(RenderMode mode) { options_.mode = mode, invalidate(); }
void Renderer::set_strategy(RenderStrategy strategy) { options_.strategy = strategy, invalidate(); }
void Renderer::set_macrocells(MacroCellMode mode, int cell_size) {
  if (cell_size < 1) fail("--macrocell-size must be at least 1, got {}", cell_size);
  if (cell_size != mc_cell_size_) grid_ranges_.reset();
  if (mode != mc_mode_ || (mode == MacroCellMode::Grid && cell_size != mc_cell_size_)) mc_.reset();
  mc_mode_ = mode;
  mc_cell_size_ = cell_size;
  invalidate();
}
void Renderer::set_step(float step, float step_max) {
  options_.step = step;
  options_.step_max = step_max;
  invalidate();
}
void Renderer::set_light(const DirectionalLight& light) { options_.light = light, invalidate(); }
void Renderer::set_background(Vec3f rgb) { options_.background = rgb, invalidate(); }
void Renderer::set_shading(bool shade) { options_.shade = shade, invalidate(); }
void Renderer::set_size(int width, int height) {
  options_.width = width;
  options_.height = height;
  invalidate();
}
void Renderer::set_seed(uint32_t seed) { options_.seed = seed, invalidate(); }
void Renderer::set_samples_per_iteration(int k) { options_.samples_per_iteration = k, invalidate(); }
void Renderer::set_density(float density_scale) { options_.density_scale = density_scale, invalidate(); }
void Renderer::set_ray_packets(bool on) { options_.ray_packets = on, invalidate(); }
void Renderer::set_mlp_path(cuda::MlpPath mlp) { mlp_ = mlp, invalidate(); }
void Renderer::set_options(const RenderOptions& options) { options_ = options, invalidate(); }

// Macro-cells of the mode: grid needs a volume, online a model trained by vnr (its recorded value
// ranges), off is one cell. Grid ranges are computed on the device that renders, once per cell size:
// switching modes back and forth (bench render's cells) does not scan the volume again.
const MacroCells& Renderer::macrocells() {
  if (!mc_) {
    switch (mc_mode_) {
      case MacroCellMode::Grid:
        if (!volume_)
          fail("--macrocells grid needs the ground-truth volume: pass it with --volume (or use online/off)");
        if (!grid_ranges_)
          grid_ranges_ = device_ == Device::Cuda ? gpu_value_ranges_from_grid(view_of(*volume_), mc_cell_size_)
                                                 : value_ranges_from_grid(view_of(*volume_), mc_cell_size_);
        mc_.emplace(*grid_ranges_, box_);
        break;
      case MacroCellMode::Online:
        if (!model_ || !model_->macrocells)
          fail("--macrocells online needs a model trained by vnr (it records the value ranges of its training "
               "samples); use grid or off");
        mc_.emplace(*model_->macrocells, box_);
        break;
      case MacroCellMode::Off:
      default:
        mc_ = MacroCells::single(model_ ? model_->dims : volume_->dims, box_);
    }
    mc_tf_current_ = false;
  }
  if (!mc_tf_current_) {
    mc_->update(tf_);
    mc_tf_current_ = true;
  }
  return *mc_;
}

// The one place the backend is created (make_renderer picks the CPU or GPU renderer for the device).
FrameRenderer& Renderer::backend() {
  if (!backend_) {
    const MacroCells& mc = macrocells();
    backend_ = make_renderer(device_, field(), box_, mc, tf_, camera_, options_, mlp_);
  }
  return *backend_;
}

const Image& Renderer::render_frame(RenderStats* stats) {
  FrameRenderer& r = backend();
  if (frames_ == 0) accumulated_ = Image(options_.width, options_.height);
  r.render_frame(uint32_t(frames_), frame_, stats);
  accumulate_frame(accumulated_, frame_, frames_, &m2_);
  ++frames_;
  return accumulated_;
}

int Renderer::render_until_converged(const Convergence& c, RenderStats* stats,
                                     const std::function<void(int, double)>& progress) {
  if (!(c.noise >= 0) || c.min_frames < 1 || c.max_frames < c.min_frames)
    fail("convergence needs a noise of at least 0 and 1 <= min_frames <= max_frames, got {}, {}, {}", c.noise,
         c.min_frames, c.max_frames);
  while (frames_ < c.max_frames) {
    render_frame(stats);
    const double n = noise();  // a pass over the image
    if (progress) progress(frames_, n);
    if (frames_ >= c.min_frames && n <= c.noise) break;
  }
  return frames_;
}

void Renderer::render_frame_resident(uint32_t frame, RenderStats* stats) {
  backend().render_frame_resident(frame, stats);
}

void Renderer::save(const std::string& path) const {
  if (frames_ == 0) fail("nothing rendered to save to '{}'", path);
  write_image(path, accumulated_);
}

double field_query_rate(const Renderer& renderer, double seconds) {
  if (renderer.device() == Device::Cuda) {
    if (!renderer.model()) return 0;
    cuda::GpuNetwork gn(*renderer.model()->net, renderer.mlp_path());
    const int64_t n = int64_t(1) << 22;
    return double(n) / gn.time_resident(n, 10).seconds;
  }
  const Field& field = renderer.field();
  const int64_t n = 1 << 20;
  std::vector<float> x(n), y(n), z(n), v(n);
  Pcg32 rng(42);
  for (int64_t i = 0; i < n; ++i) x[i] = rng.next_float(), y[i] = rng.next_float(), z[i] = rng.next_float();
  field.query(x.data(), y.data(), z.data(), n, v.data());  // warm-up
  std::vector<double> rates;
  const auto t_all = std::chrono::steady_clock::now();
  while (rates.size() < 3 || (seconds_since(t_all) < seconds && rates.size() < 50)) {
    const auto t0 = std::chrono::steady_clock::now();
    field.query(x.data(), y.data(), z.data(), n, v.data());
    rates.push_back(double(n) / seconds_since(t0));
  }
  return upper_median(rates);
}

double orbit_frame_rate(Renderer& r, const RenderOptions& options, MacroCellMode mc, const RenderOrbit& orbit,
                        const std::optional<BrickCacheSettings>& cache, RenderStats* total) {
  if (orbit.frames < 1 || orbit.warmup < 0) fail("an orbit needs at least one timed frame and no negative warm-up");
  const auto camera_of = [&](int i) {
    return orbit_camera(r.box(), 360.0f * float(i) / float(orbit.frames), orbit.elevation, orbit.fovy);
  };
  r.set_options(options);
  r.set_macrocells(mc, orbit.macrocell_size);
  r.set_cache(cache);
  if (cache)
    for (int i = 0; i < orbit.frames; ++i) r.set_camera(camera_of(i)), r.warm_cache();
  r.set_camera(camera_of(0));
  for (int i = 0; i < orbit.warmup; ++i) r.render_frame_resident(uint32_t(i));
  std::vector<double> times;
  for (int i = 0; i < orbit.frames; ++i) {
    r.set_camera(camera_of(i));
    RenderStats st;
    r.render_frame_resident(uint32_t(i), &st);
    times.push_back(st.seconds);
    total->field_samples += st.field_samples;
    total->host_syncs += st.host_syncs;
    total->iterations += st.iterations;
    total->seconds += st.seconds;
    total->frames += 1;
  }
  return 1.0 / upper_median(times);
}

}  // namespace vnr
