#pragma once
// ViewerEngine's insides, shared by viewer_engine.cpp (public calls, the engine thread), viewer_training.cpp
// (the training run), viewer_views.cpp (frames and slices) and viewer_tf.cpp (transfer functions).
//
// Locking: `mu` guards what every thread sees (the state, pending requests, losses, the newest frame);
// `work_mu` is held by the engine thread while it trains or renders, so save_model never sees a step
// half done. Everything under "engine thread" is touched only with work_mu held.
#include <array>
#include <atomic>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>
#include "vnr/fields/brick_cache.h"
#include "vnr/fields/fields.h"
#include "vnr/model.h"
#include "vnr/renderer.h"
#include "vnr/train/decoder.h"
#include "vnr/train/series.h"
#include "vnr/train/session.h"
#include "vnr/viewer.h"

namespace vnr {

// The settings one iteration of the engine thread works with (a copy taken under mu).
struct ViewerSnapshot {
  ViewerState state;
  bool interacting = false;
  uint64_t epoch = 0;          // grows with every change that changes an image
  uint64_t tf_epoch = 0;       // ... of the transfer function
  uint64_t options_epoch = 0;  // ... of the render settings or the viewport
  bool reset = false;
  std::optional<double> reset_learning_rate;
  std::optional<int> timestep;
  std::optional<std::array<float, 2>> cursor;  // over the network view, [0, 1]^2
};

// A field to render and its macro-cells, rebuilt when what it shows changes.
struct ViewContent {
  std::unique_ptr<RenderableField> field;
  std::unique_ptr<CachedField> cache;  // in front of field (viewer_wants_cache)
  std::shared_ptr<Decoder> decoder;    // what the cache decodes with
  const RenderableField& drawn() const { return cache ? *cache : *field; }
  std::unique_ptr<MacroCells> mc;
  uint64_t version = ~uint64_t(0);  // model or volume version it was built for
  MacroCellMode mode = MacroCellMode::Off;
  uint64_t tf_epoch = ~uint64_t(0);  // mc->update(tf) done for
  // The model version of the network's parameters and macro-cells, where training on the GPU changed only
  // those since `version` (renderers refresh them in place, from device_half: the trainer's copy).
  uint64_t params_version = ~uint64_t(0);
  const void* device_half = nullptr;
};

// One view's renderer and progressive accumulation.
struct ViewPass {
  std::unique_ptr<FrameRenderer> backend;
  uint64_t content_version = ~uint64_t(0), tf_epoch = ~uint64_t(0), options_epoch = ~uint64_t(0);
  uint64_t params_version = ~uint64_t(0);  // ViewContent::params_version its backend holds
  bool coarse = false;
  uint64_t cache_version = 0;  // CachedField::content_version the accumulation started from
  Camera camera;
  int count = 0;              // frames averaged (in the backend: FrameRenderer::render_mean_rgba8)
  int width = 0, height = 0;
  std::vector<uint8_t> rgba;  // their mean as RGBA8
};

// The training run (engine thread).
struct ViewerRun {
  std::shared_ptr<SwitchableSampler> sampler;  // a series: switching the timestep keeps the optimizer
  std::unique_ptr<TrainingSession> session;
  std::atomic<TrainingSession*> active{nullptr};  // for stop() from other threads
  int64_t step_base = 0;        // steps of earlier sessions (GPU: a new trainer per timestep)
  double seconds_base = 0;
  size_t losses_published = 0;  // of the current session
  std::optional<PsnrProbe> probe;
  std::unique_ptr<Decoder> probe_decoder;  // on the GPU: the probe's voxels from the trainer's parameters
  int64_t probe_step = -1;      // global step of the last probe (-1: none)
  double probe_seconds = 0;
  std::vector<std::array<double, 2>> new_psnr;  // probes not yet published
  bool continuous = false;
  int64_t switch_every = 0, switch_at = 0;
  double budget_carry = 0;  // seconds of earlier chunks' budgets that whole steps left over (or overdrew)
  int64_t steps() const { return step_base + (session ? session->steps_done() : 0); }
  double seconds() const { return seconds_base + (session ? session->training_seconds() : 0); }
};

struct ViewerEngine::Impl {
  // ---- fixed after construction
  ViewerSetup setup;
  ViewerInfo info;
  RenderInput input;               // scene, model input (and its ground truth before it moves to `volume`)
  std::unique_ptr<Model> created;  // the model trained from a volume input
  Model* model = nullptr;
  ModelConfig config;              // of the model (resets)
  std::vector<float> initial_params;  // a model input's own parameters (reset restores them)
  Device render_device = Device::Cpu, train_device = Device::Cpu;
  Precision inference = Precision::FP32;
  Vec3f box;
  ViewerState initial;             // defaults (reset_camera)
  bool online_available = false;   // online macro-cells: recorded in the model, or from training

  // ---- engine thread (work_mu)
  std::mutex work_mu;
  std::unique_ptr<Volume> volume;  // the current timestep (null: no volume)
  ViewerRun run;
  uint64_t model_version = 0, volume_version = 0;
  uint64_t published_epoch = 0;  // of the last frame published
  TransferFunction tf;  // of tf_epoch below; backends point into it
  uint64_t built_tf_epoch = ~uint64_t(0);
  ViewContent net_content, truth_content;
  ViewPass net_pass, truth_pass;
  std::optional<ValueRangeGrid> grid_ranges;  // of volume_version grid_ranges_version
  uint64_t grid_ranges_version = ~uint64_t(0);
  struct SliceCache {
    int axis = -1, index = -1;
    uint64_t model_version = ~uint64_t(0), volume_version = ~uint64_t(0);
    std::vector<ViewerImage> images;
    std::unique_ptr<Decoder> decoder;  // on the GPU kept while training: it takes the trainer's parameters
  } slices;
  double last_render_seconds = 0;  // of the last frame rendered: what the automatic training budget follows

  // ---- shared (mu)
  mutable std::mutex mu;
  std::condition_variable wake_cv;
  mutable std::condition_variable frame_cv;
  ViewerState state;
  bool interacting = false;
  std::optional<std::array<float, 2>> cursor;  // ViewerEngine::set_cursor
  uint64_t epoch = 1, tf_epoch = 1, options_epoch = 1;
  uint64_t complete_epoch = 0;  // the engine rendered everything there is for this epoch
  bool pending_reset = false;
  std::optional<double> pending_learning_rate;
  std::optional<int> pending_timestep;
  std::vector<float> losses;
  std::vector<std::array<double, 2>> psnr;
  std::vector<uint64_t> fine_histogram;  // kFineBins counts of the normalised values
  std::shared_ptr<const ViewerFrame> latest;
  uint64_t latest_epoch = 0;
  uint64_t next_frame_id = 1;
  bool stopping = false, stopped = false;
  std::atomic<bool> halting{false};  // stop(): no more steps or frames
  std::thread thread;

  static constexpr int kFineBins = 65536;

  // viewer_engine.cpp
  void open(const ViewerSetup& s);
  void thread_main();
  bool has_work_locked() const;
  void iterate(const ViewerSnapshot& snap);
  void bump_locked(bool image_changed);
  void record_error(const std::string& message, bool pause_training);

  // viewer_training.cpp
  void create_session();
  void apply_reset(std::optional<double> learning_rate);
  void load_timestep(int t);
  double train_chunk(const ViewerSnapshot& snap);  // returns the training seconds it took
  bool keep_training();  // still running, nothing pending (a chunk ends early otherwise)
  void take_probe();
  Decoder& current_decoder(std::unique_ptr<Decoder>& slot, Device device);
  void publish_training();
  std::string save(const std::string& name);

  // viewer_views.cpp
  // Renders what the snapshot needs; returns false when every image was already complete.
  bool render(const ViewerSnapshot& snap, bool* refined, int* accumulated);
  bool render_slices(const ViewSettings& view);
  void update_network_content(MacroCellMode mode, bool cache);
  std::unique_ptr<MacroCells> network_macrocells(MacroCellMode mode);
  void update_truth_content();
  const ValueRangeGrid& volume_ranges();
  std::vector<ViewerImage> frame_images(const ViewerSnapshot& snap) const;
  void compute_histogram();
};

// viewer_tf.cpp: the default editor model for a table, and a table as the editor model.
ViewerTf viewer_tf_from_table(const TransferFunction& tf);
void check_viewer_tf(const ViewerTf& tf);
// viewer_views.cpp
RenderOptions viewer_render_options(const ViewerRender& r, const Scene& scene, int width, int height);
int viewer_max_frames(const ViewerRender& r);
// The network view draws from its brick cache: strategy cache, or auto unless the network trains on the
// GPU and is drawn there. Then each chunk turns every brick stale and the cache spends 10 ms a frame
// decoding them again, one launch each, where the renderer takes the trainer's parameters device to device
// and draws a whole 768x768 frame of the network in a few ms, the model of the moment.
bool viewer_wants_cache(const ViewerRender& r, bool gpu_training);
bool same_camera(const Camera& a, const Camera& b);

}  // namespace vnr
