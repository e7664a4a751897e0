#pragma once
// vnr::ViewerEngine: the interactive system of the paper ("Online Training and Rendering") as a library
// object — what `vnr view` serves to browsers, and what any other front end (Python, a desktop app)
// can drive. It owns the scene (a volume and/or a model, camera, transfer function, render settings),
// one training run, and one engine thread that interleaves training steps and frames exactly as the
// paper's loop does (train a budget, render the current network, repeat). Every public call is
// thread-safe and returns at once: setters change the settings under a lock and wake the engine
// thread; frames and state are published as immutable snapshots that readers poll or wait for. A slow
// reader simply sees fewer frames (the newest replaces the previous one).
//
//   vnr::ViewerSetup setup;  setup.input = "bonsai.json";  setup.save_dir = "models";
//   vnr::ViewerEngine engine(setup);              // opens everything, starts the engine thread
//   engine.start_training();
//   auto frame = engine.wait_frame(0, 1.0);       // the first frame (RGBA8 images)
//   engine.set_camera(cam, /*interacting*/ true); // coarse frames until a set_camera(.., false)
//
// Protocol, layouts and the progressive-refinement rules: docs/VIEWER.md.
#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>
#include "vnr/camera.h"
#include "vnr/image.h"
#include "vnr/render_settings.h"
#include "vnr/volume.h"

namespace vnr {

struct ViewerSetup {
  std::string input;         // a volume (sidecar, raw, NRRD), a model (.vnr / BSON), a scene or a series
  std::string ground_truth;  // a volume of the model's dims ("" = none): dual view, slices, training
  VolumeOpenOptions volume_options;
  std::string config = "paper";  // the model trained from a volume: preset or tiny-cuda-nn JSON
  std::string device = "auto";   // auto | cpu | cuda: renderer and trainer
  std::string save_dir;          // save_model writes only inside it; "" = saving is refused
  bool train = false;            // start training at once
  int64_t batch = 65536;
  uint32_t seed = 1337;
  // The brick cache a model renders from (docs/RENDERING.md; on the GPU the renderer reads a copy): its
  // memory (0: a quarter of the memory available, at most 4 GiB) and the voxels it decodes the model at
  // (0: the model's dims).
  uint64_t cache_budget = 0;
  Int3 cache_dims{0, 0, 0};
};

// What does not change while the engine runs.
struct ViewerInfo {
  std::string description;  // "volume bonsai.json", "model bonsai.vnr (ground truth bonsai.json)"
  Int3 dims;
  DType source_dtype = DType::Float32;
  double lo = 0, hi = 1;  // value range in original units (of the first timestep)
  bool has_volume = false, has_model = false, can_train = false;
  int n_timesteps = 1;
  std::string device;  // "cpu" or "cuda (NVIDIA H200)"
  std::string config;  // config name or file of the trained model
  int64_t n_params = 0;
  std::vector<std::string> colormaps;  // the TF presets
  std::string save_dir;                // "" when saving is refused
};

enum class ViewLayout { Network, Truth, SideBySide, Split };

struct ViewSettings {
  ViewLayout layout = ViewLayout::Network;  // default: SideBySide when a volume is at hand
  float split = 0.5f;                       // Split: where the divider is (the page composites)
  bool slice = false;                       // also the slice images (truth, network, difference)
  int slice_axis = 2;                       // 0 = x, 1 = y, 2 = z
  float slice_position = 0.5f;              // in [0, 1] along the axis
};

// The transfer-function editor's model: colours from a colour map, opacity from control points, over a
// window of the normalised value range. to_transfer_function() builds the renderer's table.
struct ViewerTf {
  std::string colormap = "ramp";           // a preset's colours, or "custom" (custom_colors)
  std::vector<Vec3f> custom_colors;        // "custom": evenly spaced over the window
  std::vector<std::array<float, 2>> opacity;  // (x in [0,1] across the window, opacity per voxel step), sorted by x
  float lo = 0, hi = 1;                    // the window over normalised values [0, 1]
};
struct TransferFunction;  // vnr/renderer.h
TransferFunction to_transfer_function(const ViewerTf& tf);

// The viewer's defaults of what a rendering is: strategy auto (the brick cache, but the network itself
// on the GPU while it trains), online macro-cells (adjusted to what the input allows), the light from
// (0.7, 0.9, 0.4).
inline Vec3f viewer_default_light() { return normalize(Vec3f{0.7f, 0.9f, 0.4f}); }
inline RenderSettings viewer_render_defaults() {
  RenderSettings s;
  s.strategy = "auto";
  s.macrocells = "online";
  s.light = viewer_default_light();
  return s;
}

// How the viewer renders (the `render` message): the library's RenderSettings for what a rendering is,
// with its names and checks -- mode, strategy (cache: a model draws from its brick cache, on the GPU from
// a copy in GPU memory, full-resolution frames while the camera moves, docs/RENDERING.md; auto: the same
// but while the network trains on the GPU, where it is drawn itself; on the GPU each view by its fastest
// strategy;
// streaming or inshader: the field itself), step, shade, light, density, macrocells (online, grid, off)
// -- while the view's size, camera and transfer function are the viewer's own state and RenderSettings'
// other keys do not apply; then what only an interactive view has.
struct ViewerRender {
  RenderSettings settings = viewer_render_defaults();
  int max_frames = 0;    // frames accumulated once still; 0 = per mode (8 / 16 / 256)
  int coarse_scale = 2;  // while interacting: width / coarse_scale x height / coarse_scale, 1 frame
};

enum class TrainingState { Unavailable, Idle, Running, Paused };

struct ViewerTraining {
  TrainingState state = TrainingState::Unavailable;
  int64_t step = 0;
  float loss = 0;                        // of the last step
  double samples_per_second = 0;         // recent steps
  double seconds = 0;                    // training time so far
  double psnr = 0;                       // estimate on held-back voxels (0: none yet)
  double learning_rate = 0;              // current
  // Training time per frame (at least one step); 0 = auto: 1.5 x the last frame's render time, at least
  // 0.03 s, so training keeps about 60% of the machine whatever the frame costs.
  double budget_seconds = 0;
  int timestep = 0;                      // the target timestep
  bool continuous = false;               // the target advances every switch_every steps
  int64_t switch_every = 200;
  size_t n_losses = 0;                   // losses(from) has this many
};

// A snapshot of everything a client shows; version grows with every change.
struct ViewerState {
  uint64_t version = 0;
  Camera camera;
  int width = 512, height = 512;  // the viewport
  ViewSettings view;
  ViewerTf tf;
  ViewerRender render;
  ViewerTraining training;
  std::string last_error;  // of the engine thread (e.g. training diverged); error_count grows with each
  uint64_t error_count = 0;
};

// One published frame: every image the layout needs, 8-bit RGBA (round(255 * clamp(c, 0, 1)), as PNG
// output), row 0 at the top.
struct ViewerImage {
  std::string view;  // "network", "truth", "slice_truth", "slice_network", "slice_difference"
  int width = 0, height = 0;
  std::vector<uint8_t> rgba;
};
struct ViewerFrame {
  uint64_t id = 0;        // grows by one per published frame
  uint64_t state_version = 0;  // ViewerState::version of the settings it was rendered with
  bool refined = false;   // full viewport resolution (not a coarse interaction frame)
  int accumulated = 0;    // frames averaged into the network image
  double render_seconds = 0;
  double train_seconds = 0;  // training time before this frame
  // The brick cache of the network view (bricks < 0: none): bricks decoded, of them stale (from an
  // earlier step of training), bricks the view still waits for.
  int64_t cache_bricks = -1, cache_stale = 0, cache_pending = 0;
  int64_t step = 0;
  std::vector<ViewerImage> images;
};

class ViewerEngine {
public:
  // Opens the input (one clear vnr::Error on bad input) and starts the engine thread.
  explicit ViewerEngine(const ViewerSetup& setup);
  ~ViewerEngine();  // stop()
  ViewerEngine(const ViewerEngine&) = delete;
  ViewerEngine& operator=(const ViewerEngine&) = delete;
  void stop();  // ends the engine thread (after the current step or frame); idempotent

  const ViewerInfo& info() const;
  ViewerState state() const;
  // The newest frame with id > after_id, waiting up to timeout_seconds; null on timeout or after stop().
  std::shared_ptr<const ViewerFrame> wait_frame(uint64_t after_id, double timeout_seconds) const;
  // Losses of steps [from, n_losses) and the PSNR estimates (step, dB) so far.
  std::vector<float> losses(size_t from) const;
  std::vector<std::array<double, 2>> psnr_history() const;
  // Histogram of the normalised values (truth volume, else decoded network samples), `bins` bins.
  std::vector<uint32_t> histogram(int bins = 256) const;

  // Setters: invalid values throw vnr::Error naming the value; nothing changes then.
  void set_camera(const Camera& camera, bool interacting);
  void reset_camera();  // the scene's camera, else orbit_camera(box, 0, 0, 30)... as `vnr render`
  void set_viewport(int width, int height);  // 16..4096 each
  // Where the user's cursor is over the network view, (x, y) in [0, 1], row 0 at the top (none: not
  // over it): the brick cache decodes the bricks under it first. Changes no image.
  void set_cursor(std::optional<std::array<float, 2>> xy);
  void set_view(const ViewSettings& view);
  void set_tf(const ViewerTf& tf);
  void set_render(const ViewerRender& render);
  // An instantvnr TF file, a whole instantvnr scene (camera too) or vnr's TF/scene JSON, as text.
  void load_tf_json(const std::string& text);
  std::string tf_json() const;     // the current TF as an instantvnr TF file
  std::string scene_json() const;  // camera + TF as an instantvnr scene

  // Training (can_train only, else vnr::Error).
  void start_training();
  void pause_training();
  void reset_training(std::optional<double> learning_rate = {});  // fresh parameters, step 0, Idle
  void set_training_budget(double seconds_per_frame);             // 0 (auto) or 0.001..10
  void set_timestep(int t);                                       // [0, n_timesteps)
  void set_continuous(bool on, int64_t switch_every);

  // Writes the current model atomically as save_dir/name (name: [A-Za-z0-9._-]+, ".vnr" appended when
  // missing, no path separators); returns the path written.
  std::string save_model(const std::string& name);
  // The current view's network image (truth when the layout shows only truth), refined: full viewport
  // resolution with at least one full frame; waits for it up to timeout_seconds. As the page shows it:
  // 8 bits a channel (values k / 255, so to_rgba8 and PNG give back the frame's bytes), alpha 1.
  Image screenshot(double timeout_seconds = 10);

private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace vnr
