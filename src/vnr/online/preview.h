#pragma once
// Training previews: the online loop (online_loop.h) without a window. Every `every` training steps
// the current model is rendered (macro-cells from the training samples so far) and written to
// DIR/step_NNNNNN.png (step zero-padded to 6 digits, wider past 999999), atomically. `vnr train
// --preview-every N --preview-dir DIR` runs it as side work of its TrainingSession.
#include <cstdint>
#include <memory>
#include <string>
#include "vnr/online/online_loop.h"

namespace vnr {

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
