#include "vnr/online.h"
#include "vnr/fields/fields.h"
#include "vnr/render/macrocell.h"
#include "vnr/render/renderer.h"
#include "vnr/train/session.h"
#include <algorithm>
#include <chrono>
#include "vnr/error.h"

namespace vnr {

std::vector<float> OnlineLoop::loss_history() const { return session_.trainer().losses(); }

namespace {
double seconds_between(std::chrono::steady_clock::time_point a, std::chrono::steady_clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}
}  // namespace

OnlineLoop::OnlineLoop(TrainingSession& session, Int3 dims, const TransferFunction& tf, const Camera& camera,
                       const RenderOptions& options, MacroCellMode mc, Device device)
    : session_(session), device_(device), dims_(dims), box_{float(dims.x), float(dims.y), float(dims.z)}, tf_(tf),
      camera_(camera), opt_(options), mc_mode_(mc) {
  if (dims.x < 1 || dims.y < 1 || dims.z < 1) fail("online rendering: invalid volume dims");
  if (mc == MacroCellMode::Grid)
    fail("online rendering builds its macro-cells from the training samples: use online or off, not grid");
  const Trainer& trainer = session.trainer();
  if (mc == MacroCellMode::Online) {
    if (!trainer.has_online_ranges())
      fail("online macro-cells need the trainer's online value ranges (Trainer::enable_online_ranges)");
    // Checked once here (a merge of empty grids: cheap) so that mistakes fail before any training.
    const ValueRangeGrid g = trainer.online_ranges();
    if (!(g.volume_dims == dims))
      fail("the trainer records value ranges for {}x{}x{} voxels, but the loop renders {}x{}x{}", g.volume_dims.x,
           g.volume_dims.y, g.volume_dims.z, dims.x, dims.y, dims.z);
  }
  if (tf_.table.size() < 2) fail("the transfer function needs at least 2 entries");
  last_loss_ = trainer.last_loss();
}

OnlineLoop::~OnlineLoop() = default;

float OnlineLoop::train(int64_t n) {
  if (n < 0) fail("the number of training steps must not be negative (got {})", n);
  auto t0 = std::chrono::steady_clock::now();
  if (n > 0) {
    session_.run(n);
    last_loss_ = session_.last_loss();
  }
  pending_train_seconds_ += seconds_between(t0, std::chrono::steady_clock::now());
  return last_loss_;
}

bool OnlineLoop::refresh() {
  Trainer& trainer = session_.trainer();
  const uint64_t step = trainer.steps_done();
  if (model_dirty_ || step != rendered_step_ || !renderer_) {
    // New parameters (and, online, new samples): everything the renderer refers to is rebuilt.
    renderer_.reset();
    trainer.download();
    field_ = std::make_unique<NetworkField>(trainer.network(), dims_);
    if (mc_mode_ == MacroCellMode::Online)
      mc_ = std::make_unique<MacroCells>(trainer.online_ranges(), box_);
    else
      mc_ = std::make_unique<MacroCells>(MacroCells::single(dims_, box_));
    mc_->update(tf_);
    renderer_ = make_renderer(device_, *field_, box_, *mc_, tf_, camera_, opt_, cuda::MlpPath::Auto);
    rendered_step_ = step;
    model_dirty_ = tf_dirty_ = options_dirty_ = camera_dirty_ = false;
    return true;
  }
  if (tf_dirty_ || options_dirty_) {
    // The renderer holds views of tf_ and of the macro-cells' opacities: rebuilt after them.
    renderer_.reset();
    if (tf_dirty_) mc_->update(tf_);
    renderer_ = make_renderer(device_, *field_, box_, *mc_, tf_, camera_, opt_, cuda::MlpPath::Auto);
    tf_dirty_ = options_dirty_ = camera_dirty_ = false;
    return true;
  }
  if (camera_dirty_) {
    renderer_->set_camera(camera_);
    camera_dirty_ = false;
    return true;
  }
  return false;
}

const Image& OnlineLoop::render_frame() {
  auto t0 = std::chrono::steady_clock::now();
  if (refresh()) acc_count_ = 0;
  auto t1 = std::chrono::steady_clock::now();
  renderer_->render_frame(uint32_t(acc_count_), frame_);
  if (acc_.width != frame_.width || acc_.height != frame_.height) acc_ = Image(frame_.width, frame_.height);
  if (acc_count_ == 0)
    acc_.pixels = frame_.pixels;  // = accumulate_frame(acc_, frame_, 0), without its arithmetic
  else
    accumulate_frame(acc_, frame_, acc_count_);
  ++acc_count_;
  auto t2 = std::chrono::steady_clock::now();
  OnlineFrame f;
  f.step = session_.trainer().steps_done();
  f.accumulated = acc_count_;
  f.loss = last_loss_;
  f.train_seconds = pending_train_seconds_;
  f.update_seconds = seconds_between(t0, t1);
  f.render_seconds = seconds_between(t1, t2);
  frames_.push_back(f);
  pending_train_seconds_ = 0;
  return acc_;
}

int64_t OnlineLoop::run(int64_t total_steps, int64_t steps_per_frame, const FrameCallback& on_frame) {
  if (total_steps < 0) fail("the number of training steps must not be negative (got {})", total_steps);
  if (steps_per_frame < 1) fail("steps per frame must be at least 1 (got {})", steps_per_frame);
  int64_t done = 0;
  while (done < total_steps) {
    const int64_t n = std::min(steps_per_frame, total_steps - done);
    train(n);
    done += n;
    const Image& img = render_frame();
    if (on_frame && !on_frame(img, frames_.back())) break;
  }
  return done;
}

void OnlineLoop::set_camera(const Camera& camera) {
  camera_ = camera;
  camera_dirty_ = true;
}

void OnlineLoop::set_transfer_function(const TransferFunction& tf) {
  if (tf.table.size() < 2) fail("the transfer function needs at least 2 entries");
  tf_ = tf;
  tf_dirty_ = true;
}

void OnlineLoop::set_options(const RenderOptions& options) {
  opt_ = options;
  options_dirty_ = true;
}

}  // namespace vnr
