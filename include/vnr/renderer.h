#pragma once
// vnr::Renderer: renders a Model or a Volume (the ground truth) on an explicit device, with progressive
// accumulation. Every setting can change between frames; any change restarts the accumulation, so the
// image after N frames equals what a fresh renderer with the same settings gives after N frames.
//   vnr::Renderer r(model, vnr::Device::Cpu);
//   r.set_transfer_function("cool-warm"); r.set_size(512, 512);
//   for (int i = 0; i < 16; ++i) r.render_frame();
//   r.save("out.png");
// Backends: the CPU's CpuRenderer and the GPU's GpuRenderer (src/vnr/render*), made by make_renderer.
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>
#include "vnr/camera.h"
#include "vnr/device.h"
#include "vnr/image.h"
#include "vnr/model.h"
#include "vnr/opaque.h"
#include "vnr/render_options.h"
#include "vnr/render_settings.h"
#include "vnr/scene.h"
#include "vnr/transfer_function.h"
#include "vnr/volume.h"

namespace vnr {

class RenderableField;  // fields/fields.h: what a renderer samples (a grid, a network, the brick cache)
class CachedField;      // fields/brick_cache.h
class FrameRenderer;    // render/renderer.h: a backend (CPU or GPU)
class MacroCells;       // render/macrocell.h

// True when `path` holds a model (.vnr by its magic, or instantvnr BSON); false for anything that
// describes a volume (sidecars, scenes, NRRD, raw).
bool is_model_path(const std::string& path);

// A render input opened from files: a model (with an optional ground-truth volume of the same dims)
// or a volume; an instantvnr scene given as the volume also brings its camera and transfer function.
struct RenderInput {
  std::optional<Model> model;
  std::optional<Volume> volume;
  Scene scene;
  std::string description;  // "model NAME" or "volume NAME", for messages and reports
};
// The model's network infers with `precision` (in-shader evaluation and batched queries alike).
RenderInput open_render_input(const std::string& input, const std::string& ground_truth,
                              const VolumeOpenOptions& volume_options, Precision precision);

// The device to render a model (null: a volume) on, from "auto", "cpu" or "cuda": auto takes a visible
// GPU when the field can run there, else the CPU, with the reason in *note; "cuda" for a network the
// GPU cannot run fails with that reason.
Device choose_render_device(const std::string& name, const Model* model, std::string* note = nullptr);

// The default macro-cell mode: online for a model that carries ranges, grid when a volume is at hand,
// else off.
MacroCellMode default_macrocell_mode(const Model* model, const Volume* volume);

// When Renderer::render_until_converged stops: once the image's noise (Renderer::noise) is at most
// `noise`, after at least min_frames frames, or after max_frames.
struct Convergence {
  double noise = 1.0 / 255;  // one step of an 8-bit image, RMS
  int min_frames = 4, max_frames = 256;
};

class Renderer {
public:
  // Renders the model; ground_truth (same dims) enables MacroCellMode::Grid. Both must outlive the
  // renderer; the network's inference precision must be set before.
  Renderer(const Model& model, Device device, const Volume* ground_truth = nullptr);
  // Renders the volume itself.
  Renderer(const Volume& volume, Device device);
  // Renders what the input holds (its model if any), starting from the input's scene; the input must
  // outlive the renderer and stay where it is.
  Renderer(const RenderInput& input, Device device);
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  // Settings. Defaults: 768x768, ray marching, streaming, the "ramp" preset, the default macro-cells
  // (default_macrocell_mode, 16 voxels a cell), orbit_camera(box(), 0, 0, 30).
  void set_camera(const Camera& camera);
  void set_transfer_function(const TransferFunction& tf);
  void set_transfer_function(const std::string& preset_or_file);  // a preset name or instantvnr TF JSON
  // Camera, transfer function, light and background from a scene; what it lacks gets the defaults.
  void set_scene(const Scene& scene);
  void set_scene(const std::string& scene_file);  // instantvnr scene JSON or vnr scene JSON
  void set_mode(RenderMode mode);
  void set_strategy(RenderStrategy strategy);
  // The faster strategy for this renderer's field, device and mode (fastest_render_strategy): what
  // --strategy auto sets; streaming where in-shader cannot run.
  RenderStrategy automatic_strategy() const;
  // False for a network the GPU's in-shader MLP cannot run (its 16-wide tiles: docs/RENDERING.md), which
  // RenderStrategy::InShader then refuses.
  bool can_render_inshader() const;
  // The brick cache in front of a model's field (fields/brick_cache.h, docs/RENDERING.md): decoded
  // bricks at the level of detail the view needs; nullopt = off (the default). On the GPU the renderer
  // reads a copy of the same cache in GPU memory, decoded by the model on the GPU, its misses reading the
  // nearest decoded coarser level. A volume has nothing to cache. The cache is kept across every other
  // setting.
  void set_cache(std::optional<BrickCacheSettings> settings);
  const std::optional<BrickCacheSettings>& cache() const { return cache_settings_; }
  // A front end's --strategy: "auto" (the brick cache for a model when `frames` will be accumulated,
  // 0 = unknown, at least kCacheFrames: warming it costs about ten network frames; then the faster
  // execution strategy for the field),
  // "cache" (the cache with that), "streaming" or
  // "inshader" (no cache). cache_budget: bytes of the cache's pool (0 = default_cache_budget());
  // cache_dims: the voxels the cache decodes the model at (0 = the model's dims; any size).
  static constexpr int kCacheFrames = 8;
  void choose_strategy(const std::string& choice, uint64_t cache_budget = 0, Int3 cache_dims = {0, 0, 0},
                       int frames = 0);
  // With a cache: renders one frame of the current view (not accumulated) and decodes every brick it
  // asked for, so the frames after it read the cache alone (vnr render, Python render and benchmarks do
  // this before accumulating; an interactive loop does not). No-op without a cache. progress(done,
  // total) after each brick.
  void warm_cache(const std::function<void(int64_t, int64_t)>& progress = {});
  BrickCacheStats cache_stats() const;  // zeros without a brick cache
  void set_macrocells(MacroCellMode mode, int cell_size = 16);
  void set_step(float step, float step_max = 0);  // voxels; step_max 0 = 16 x step
  void set_light(const DirectionalLight& light);
  void set_background(Vec3f rgb);
  void set_shading(bool shade);
  void set_size(int width, int height);
  void set_seed(uint32_t seed);
  void set_samples_per_iteration(int k);  // streaming: K
  void set_density(float density_scale);  // path tracing
  void set_ray_packets(bool on);          // in-shader grid ray marching in SIMD packets (same image)
  void set_mlp_path(cuda::MlpPath mlp);   // GPU streaming inference
  // Every RenderOptions field at once.
  void set_options(const RenderOptions& options);

  const RenderOptions& options() const { return options_; }
  const Camera& camera() const { return camera_; }
  const TransferFunction& transfer_function() const { return tf_; }
  MacroCellMode macrocell_mode() const { return mc_mode_; }
  Device device() const { return device_; }
  cuda::MlpPath mlp_path() const { return mlp_; }
  Vec3f box() const { return box_; }     // world size of the volume box (voxel units)
  const RenderableField& field() const;  // the cache when on
  // What field() samples: "grid", "network" or "cache" (reports, fastest_render_strategy).
  const char* field_kind() const;
  const Model* model() const { return model_; }

  // Renders the next frame, adds it to the accumulation and returns the accumulated image (the mean of
  // the frames since the last change). stats (optional) accumulates the frame's statistics.
  const Image& render_frame(RenderStats* stats = nullptr);
  // Builds the macro-cells and the backend now, so that a bad setting fails here rather than at the
  // first frame (render_frame does it when needed).
  void prepare() { backend(); }
  // Renders frame number `frame` and leaves it where it was rendered (GPU memory on the GPU), without
  // accumulating: what benchmarks time.
  void render_frame_resident(uint32_t frame, RenderStats* stats = nullptr);
  // Renders frames (adding to the accumulation) until the image has converged as `c` says; progress
  // (frames, noise) after each frame. Returns the frames accumulated.
  int render_until_converged(const Convergence& c, RenderStats* stats = nullptr,
                             const std::function<void(int frames, double noise)>& progress = {});
  const Image& image() const { return accumulated_; }
  int frames() const { return frames_; }  // accumulated since the last change
  // The RMS over pixels of the accumulated image's standard error, estimated from the spread of the
  // frames (accumulated_noise; infinite before two frames).
  double noise() const;
  void save(const std::string& path) const;  // .png (8-bit) or .pfm (float)

private:
  friend struct BrickSegment render_brick_segment(Renderer& renderer, int index);  // vnr/bricks.h
  Renderer(const Model* model, const Volume* volume, Device device);
  void restart() { frames_ = 0; }
  void invalidate();
  FrameRenderer& backend();
  const MacroCells& macrocells();
  const RenderableField& source_field() const;

  const Model* model_ = nullptr;
  const Volume* volume_ = nullptr;
  Device device_;
  // The model's or the volume's field, made on first use (source_field): on the GPU a multi-brick model's
  // is its whole decode, which the brick cache does without.
  mutable std::unique_ptr<RenderableField> field_;
  std::optional<BrickCacheSettings> cache_settings_;
  std::unique_ptr<RenderableField> cache_source_;  // on the GPU: the model's CPU field (the copy never reads it)
  std::unique_ptr<CachedField> brick_cache_;
  Vec3f box_;
  RenderOptions options_;
  Camera camera_;
  TransferFunction tf_;
  MacroCellMode mc_mode_ = MacroCellMode::Off;
  int mc_cell_size_ = 16;
  cuda::MlpPath mlp_ = cuda::MlpPath::Auto;
  Opaque<ValueRangeGrid> grid_ranges_;  // Grid mode's value ranges for mc_cell_size_
  Opaque<MacroCells> mc_;  // for mc_mode_ and mc_cell_size_, opacities for tf_
  bool mc_tf_current_ = false;
  std::unique_ptr<FrameRenderer> backend_;
  Image frame_, accumulated_;
  std::vector<float> m2_;  // per pixel: the frames' squared deviations (accumulate_frame)
  int frames_ = 0;
};

// A transfer function from a preset name, transfer-function JSON text (instantvnr's or vnr's) or a file.
TransferFunction transfer_function_of(const std::string& preset_json_or_file);
// Whether transfer_function_of reads `tf` from a file (neither empty, a preset nor JSON text).
bool names_a_tf_file(const std::string& tf);

// A renderer over a model (with `volume` as its ground truth, or null) or a volume (model null), set up
// as `settings` say: what every front end renders with. `input_scene` (the input's own, e.g. an
// instantvnr scene; Scene{} for none) fills in what the settings leave out; settings.spp steers strategy
// auto (Renderer::choose_strategy). notes: what the user should know (a device fallback, residuals the
// image does not show). orbit_elevation: the camera's elevation in degrees when it orbits.
struct RenderSetup {
  std::unique_ptr<Renderer> renderer;
  float orbit_elevation = 0;
  std::vector<std::string> notes;
};
RenderSetup setup_renderer(const Model* model, const Volume* volume, const Scene& input_scene,
                           const RenderSettings& settings);

// The field's batched query rate (samples/s) on uniformly random points over about `seconds`: on the
// CPU the renderer's Field::query, on the GPU the network's resident encoding + MLP; 0 when not
// measured (a grid on the GPU).
double field_query_rate(const Renderer& renderer, double seconds);

// What `vnr bench render` times for one cell of its table: the renderer with `options` and macro-cells
// `mc` (cells of macrocell_size voxels), with `cache` a fresh brick cache warmed at every camera of the
// orbit first (what a view that has settled reads); `warmup` untimed frames, then `frames` timed ones
// with the camera orbiting 360 degrees (frame i of n from azimuth 360 i / n, at `elevation`). Returns
// frames/s of the median frame; the timed frames' statistics are added to *total.
struct RenderOrbit {
  int frames = 6, warmup = 1;
  float elevation = 0, fovy = 30;
  int macrocell_size = 16;
};
double orbit_frame_rate(Renderer& renderer, const RenderOptions& options, MacroCellMode mc, const RenderOrbit& orbit,
                        const std::optional<BrickCacheSettings>& cache, RenderStats* total);

}  // namespace vnr
