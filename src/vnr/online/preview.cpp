#include "vnr/online.h"
#include "vnr/fields/fields.h"
#include "vnr/render/macrocell.h"
#include "vnr/render/renderer.h"
#include "vnr/train/session.h"
#include <unistd.h>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <system_error>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/render/camera.h"

namespace vnr {

void check_preview_options(const PreviewOptions& o) {
  if (o.every <= 0) fail("previews need a positive number of steps between them (got {})", o.every);
  if (o.dir.empty()) fail("previews need an output directory");
  if (o.width < 1 || o.height < 1 || o.width > 32768 || o.height > 32768)
    fail("invalid preview size {}x{}", o.width, o.height);
  if (o.tf.table.size() < 2) fail("the preview transfer function needs at least 2 entries");
  if (!std::isfinite(o.azimuth) || !(o.elevation > -90 && o.elevation < 90))
    fail("preview camera: elevation must be in (-90, 90) degrees (got {})", o.elevation);
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path dir(o.dir);
  if (fs::exists(dir, ec)) {
    if (!fs::is_directory(dir, ec)) fail("preview directory '{}' exists and is not a directory", o.dir);
  } else if (!fs::create_directories(dir, ec) && ec) {
    fail("cannot create the preview directory '{}': {}", o.dir, ec.message());
  }
  // Probe: the previews are written atomically (a temporary then a rename), so that is what must work.
  const std::string probe = join_path(o.dir, ".vnr-preview-probe-" + std::to_string(::getpid()));
  try {
    write_file_atomic(probe, "");
  } catch (const Error&) {
    fail("cannot write into the preview directory '{}'", o.dir);
  }
  std::remove(probe.c_str());
}

std::string preview_path(const std::string& dir, int64_t step) {
  return join_path(dir, fmt::format("step_{:06d}.png", step));
}

TrainPreview::TrainPreview(const PreviewOptions& o, TrainingSession& session, Int3 dims) : o_(o) {
  check_preview_options(o_);
  RenderOptions ro;
  ro.width = o_.width;
  ro.height = o_.height;
  ro.mode = o_.mode;
  const Vec3f box{float(dims.x), float(dims.y), float(dims.z)};
  const Camera cam = orbit_camera(box, o_.azimuth, o_.elevation, 30);
  loop_ = std::make_unique<OnlineLoop>(
      session, dims, o_.tf, cam, ro, session.trainer().has_online_ranges() ? MacroCellMode::Online : MacroCellMode::Off);
}

double TrainPreview::write(int64_t step) {
  auto t0 = std::chrono::steady_clock::now();
  // Previews infer as `vnr render` does by default (bf16 where the CPU has it); the training run's
  // own inference precision (its final evaluation is fp32) is restored afterwards.
  struct PrecisionScope {
    Network& net;
    Precision keep;
    ~PrecisionScope() { net.set_inference_precision(keep); }
  } scope{loop_->trainer().network(), loop_->trainer().network().inference_precision()};
  scope.net.set_inference_precision(parse_precision("auto"));
  const Image& img = loop_->render_frame();
  last_path_ = preview_path(o_.dir, step);
  write_image(last_path_, img);
  ++written_;
  last_step_ = step;
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  seconds_ += s;
  return s;
}

double TrainPreview::after_step(int64_t step) {
  if (step <= 0 || step % o_.every != 0 || step == last_step_) return 0;
  return write(step);
}

double TrainPreview::finish(int64_t step) {
  if (step < 0 || step == last_step_) return 0;
  return write(step);
}

}  // namespace vnr
