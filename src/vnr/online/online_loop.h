#pragma once
// Online training and rendering (paper "Online Training and Rendering" and "Macro-Cell Optimization"):
// training steps and rendered frames interleaved on the same Network, with the macro-cells built
// from the training samples themselves.
//
// How it maps to the paper's loop. The original runs, per displayed frame, one training step and one
// frame on the same GPU stream: sample a batch -> optimise -> widen the macro-cell value ranges with
// the batch's samples -> recompute the macro-cells' max opacity -> render with the current weights.
// Here the same loop runs sequentially (both halves use every core), on any training backend:
//   train(n)        TrainingSession::run(n) on its Trainer backend (the CPU or the GPU); each step's
//                   samples widen the trainer's online value ranges (Trainer::enable_online_ranges) as
//                   they are drawn;
//   render_frame()  if the model changed since the last frame (Trainer::steps_done() moved, or
//                   model_changed() was called): bring the parameters into the Network
//                   (Trainer::download, a no-op on the CPU), merge the online ranges
//                   (Trainer::online_ranges), rebuild MacroCells from them and recompute their max
//                   opacity for the transfer function, rebuild the NetworkField (its in-shader
//                   PointEvaluator copies the weights, so it must see the new ones) and the renderer;
//                   then render one frame with the current parameters.
//   run(T, k, cb)   train(k); render_frame(); cb(...) until T steps are done: k = 1 is the paper's
//                   one-step-per-frame loop.
// The per-frame refresh is cheap next to a frame, so nothing is updated in place.
// train and render stay unaware of each other: the macro-cells pass between them as a ValueRangeGrid.
//
// Progressive accumulation: while nothing changes, consecutive frames (frame numbers 0, 1, 2, ...:
// their jitter and random numbers) are averaged, exactly as CpuRenderer::render(n) averages them. Any
// change — a training step, set_camera, set_transfer_function, set_options, model_changed — restarts
// it at frame 0, so a frame is always bit-identical to one from a freshly built CpuRenderer over the same
// network, macro-cells, camera and options.
#include <cstdint>
#include <functional>
#include <memory>
#include <vector>
#include "vnr/fields/fields.h"
#include "vnr/render/renderer.h"
#include "vnr/train/session.h"

namespace vnr {

// What one rendered frame cost and showed.
struct OnlineFrame {
  uint64_t step = 0;          // training steps done (Trainer::steps_done) when it was rendered
  int accumulated = 0;        // frames averaged into the image (1 right after any change)
  float loss = 0;             // loss of the last training step (0 before any)
  double train_seconds = 0;   // time in TrainingSession::run() through train() since the previous frame
  double update_seconds = 0;  // merging the online ranges, macro-cell max opacities, field/renderer rebuild
  double render_seconds = 0;  // FrameRenderer::render_frame + accumulation
};

class OnlineLoop {
public:
  // Trains through `session` (the one training loop: its stop token, pause and callbacks apply) and
  // renders its network on `device`; the session must outlive the loop. dims = the volume the network
  // represents (world box [0, dims], as `vnr render`). mc: Online (the session's trainer must have online
  // ranges enabled, with the same dims) or Off (one cell over the box; Grid needs a ground truth, which
  // online training does not assume).
  OnlineLoop(TrainingSession& session, Int3 dims, const TransferFunction& tf, const Camera& camera,
             const RenderOptions& options, MacroCellMode mc = MacroCellMode::Online, Device device = Device::Cpu);
  OnlineLoop(const OnlineLoop&) = delete;
  OnlineLoop& operator=(const OnlineLoop&) = delete;
  ~OnlineLoop();

  // Runs n training steps (fewer when the session is asked to stop); returns the loss of the last one
  // (the last known loss when n = 0).
  float train(int64_t n);
  // Renders one frame of the current model and returns the (accumulated) image.
  const Image& render_frame();
  // Interleaves: until `total_steps` more steps are done, train(steps_per_frame) (fewer at the end)
  // then render_frame(), then on_frame(image, frame) — return false from it to stop early. Returns the
  // steps done.
  using FrameCallback = std::function<bool(const Image&, const OnlineFrame&)>;
  int64_t run(int64_t total_steps, int64_t steps_per_frame, const FrameCallback& on_frame);

  // View and appearance; each restarts accumulation. A new transfer function recomputes the
  // macro-cells' max opacity at the next frame.
  void set_camera(const Camera& camera);
  void set_transfer_function(const TransferFunction& tf);
  void set_options(const RenderOptions& options);
  // The network's parameters were changed other than by the trainer's steps (e.g. loaded).
  void model_changed() { model_dirty_ = true; }

  const Image& image() const { return acc_; }          // the last render_frame() result
  int accumulated_frames() const { return acc_count_; }
  // Macro-cells of the last frame (null before the first one).
  const MacroCells* macrocells() const { return mc_.get(); }
  std::vector<float> loss_history() const { return session_.trainer().losses(); }
  const std::vector<OnlineFrame>& frames() const { return frames_; }  // one entry per render_frame()
  TrainingSession& session() { return session_; }
  Trainer& trainer() { return session_.trainer(); }
  Device device() const { return device_; }
  const Camera& camera() const { return camera_; }
  const TransferFunction& transfer_function() const { return tf_; }
  const RenderOptions& options() const { return opt_; }
  Vec3f box() const { return box_; }

private:
  // Brings field, macro-cells and renderer up to date; returns whether anything changed.
  bool refresh();

  TrainingSession& session_;
  Device device_;
  Int3 dims_;
  Vec3f box_;
  TransferFunction tf_;
  Camera camera_;
  RenderOptions opt_;
  MacroCellMode mc_mode_;
  // The renderer refers to the field, the macro-cells and tf_: rebuilt together (renderer last).
  std::unique_ptr<NetworkField> field_;
  std::unique_ptr<MacroCells> mc_;
  std::unique_ptr<FrameRenderer> renderer_;
  uint64_t rendered_step_ = 0;  // steps_done() the current field/macro-cells were built at
  bool model_dirty_ = true, tf_dirty_ = true, options_dirty_ = true, camera_dirty_ = true;
  Image frame_, acc_;
  int acc_count_ = 0;
  double pending_train_seconds_ = 0;
  float last_loss_ = 0;
  std::vector<OnlineFrame> frames_;
};

}  // namespace vnr
