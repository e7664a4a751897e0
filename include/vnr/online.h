#pragma once
// vnr's online training and rendering API: OnlineLoop interleaves a TrainingSession's steps with frames
// of the current model (macro-cells from the training samples); TrainPreview writes such frames to PNG
// files every N steps (the side work of a TrainingSession in `vnr train --preview-every`).
//
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
//
// Training previews: the online loop above without a window. Every `every` training steps
// the current model is rendered (macro-cells from the training samples so far) and written to
// DIR/step_NNNNNN.png (step zero-padded to 6 digits, wider past 999999), atomically. `vnr train
// --preview-every N --preview-dir DIR` runs it as side work of its TrainingSession.
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>
#include "vnr/camera.h"
#include "vnr/device.h"
#include "vnr/image.h"
#include "vnr/math.h"
#include "vnr/render_options.h"
#include "vnr/trainer.h"
#include "vnr/transfer_function.h"

namespace vnr {

class NetworkField;   // fields/fields.h
class MacroCells;     // render/macrocell.h
class FrameRenderer;  // render/renderer.h

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
  std::vector<float> loss_history() const;
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

struct PreviewOptions {
  int64_t every = 0;  // training steps between previews (> 0)
  std::string dir;    // output directory (created if missing)
  int width = 256, height = 256;
  RenderMode mode = RenderMode::RayMarch;
  TransferFunction tf = tf_preset("ramp");  // `vnr render`'s default
  float azimuth = 0, elevation = 0;          // orbit camera, as `vnr render --orbit` (default view: 0, 0)
};

// Checks the options and makes `dir` ready: creates it (with parents) if missing and writes and
// removes a probe file, so an unusable directory fails before training starts (one clear message).
void check_preview_options(const PreviewOptions& o);

// The path of the preview of `step` in `dir`: dir/step_000100.png.
std::string preview_path(const std::string& dir, int64_t step);

class TrainPreview {
public:
  // Checks the options (check_preview_options). Uses the session trainer's online value ranges as
  // macro-cells when it records them (Trainer::enable_online_ranges), else one macro-cell over the box.
  // session must outlive the preview; dims = the volume being trained.
  TrainPreview(const PreviewOptions& o, TrainingSession& session, Int3 dims);
  // Call after each training step with the number of steps done: at multiples of `every` renders and
  // writes the preview. Returns the seconds it took (0 when it wrote nothing), so that a caller can
  // leave preview time out of its training throughput.
  double after_step(int64_t step);
  // Call once after the last step: writes its preview unless after_step(step) already did (a run cut
  // short by a time limit or Ctrl-C still shows its final state). Returns the seconds it took.
  double finish(int64_t step);

  int64_t frames_written() const { return written_; }
  double seconds() const { return seconds_; }            // total time spent on previews
  const std::string& last_path() const { return last_path_; }
  const OnlineLoop& loop() const { return *loop_; }

private:
  double write(int64_t step);

  PreviewOptions o_;
  std::unique_ptr<OnlineLoop> loop_;
  int64_t written_ = 0, last_step_ = -1;
  double seconds_ = 0;
  std::string last_path_;
};

}  // namespace vnr
