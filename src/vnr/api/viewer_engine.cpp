// vnr::ViewerEngine: opening the input, the public calls (validated setters, snapshots) and the engine
// thread's loop (docs/VIEWER.md "Progressive refinement and the engine loop").
#include <chrono>
#include <cmath>
#include "vnr/api/viewer_impl.h"
#include "vnr/train/bricks.h"
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/cuda/cuda.h"
#include "vnr/train/make_trainer.h"

namespace vnr {

namespace {

using Clock = std::chrono::steady_clock;

std::string device_description(Device d) {
  if (d != Device::Cuda) return "cpu";
  const auto devices = cuda::devices();
  return devices.empty() ? "cuda" : "cuda (" + devices.front().name + ")";
}

void check_finite(Vec3f v, const char* what) {
  if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z))
    fail("{} ({}, {}, {}) is not finite", what, v.x, v.y, v.z);
}

// The renderer's own camera checks (fovy, eye != center, up not parallel); its messages start "camera:".
void check_camera(const Camera& c) {
  check_finite(c.eye, "camera eye");
  check_finite(c.center, "camera center");
  check_finite(c.up, "camera up");
  (void)make_camera_frame(c, 1, 1);
}

}  // namespace

// ---- opening -------------------------------------------------------------------------------------

void ViewerEngine::Impl::open(const ViewerSetup& s) {
  setup = s;
  if (s.batch <= 0 || s.batch % kChunk != 0) fail("batch must be a positive multiple of {}, got {}", kChunk, s.batch);
  if (s.cache_budget > 0) check_cache_budget(s.cache_budget, BrickCacheSettings{}.brick);
  inference = parse_precision("auto");
  input = open_render_input(s.input, s.ground_truth, s.volume_options, inference);
  if (input.volume) volume = std::make_unique<Volume>(std::move(*input.volume));
  input.volume.reset();
  info.n_timesteps = 1;
  if (input.model) {
    model = &*input.model;
    config = model->net->config();
    initial_params.assign(model->net->params().begin(), model->net->params().end());
    info.config = basename_of(s.input);
  } else {
    const VolumeDesc desc = describe_volume_file(s.input, s.volume_options);
    info.n_timesteps = desc.n_timesteps;
    config = load_config(s.config);
    created = std::make_unique<Model>(create_model(config, *volume, s.seed));
    model = created.get();
    model->net->set_inference_precision(inference);
    info.config = s.config;
  }
  const Int3 dims = model->dims;
  box = Vec3f{float(dims.x), float(dims.y), float(dims.z)};
  render_device = choose_render_device(s.device, model);
  info.description = input.description;
  if (input.model && volume) info.description += " (ground truth " + basename_of(s.ground_truth) + ")";
  info.dims = dims;
  info.source_dtype = volume ? volume->source_dtype : model->source_dtype;
  info.lo = volume ? volume->lo : model->lo;
  info.hi = volume ? volume->hi : model->hi;
  info.has_volume = volume != nullptr;
  info.has_model = input.model.has_value();
  info.can_train = volume != nullptr && model->trainable();  // a multi-brick model is viewed, not retrained
  info.device = device_description(render_device);
  info.n_params = int64_t(model->n_params());
  info.colormaps = tf_preset_names();
  info.save_dir = s.save_dir;
  online_available = info.can_train || model->macrocells.has_value();
  if (info.can_train) {
    train_device = choose_training_device(s.device, *model->net, dims, true, s.batch).device;
    create_session();
  }

  ViewerState& st = state;
  st.camera = camera_for(CameraRequest{}, box, input.scene.camera);
  st.tf = viewer_tf_from_table(input.scene.tf ? *input.scene.tf : tf_preset("ramp"));
  st.view.layout = volume ? ViewLayout::SideBySide : ViewLayout::Network;
  st.render.settings.macrocells =
      macrocell_mode_name(input.model ? default_macrocell_mode(model, volume.get()) : MacroCellMode::Online);
  if (input.scene.light) st.render.settings.light = input.scene.light->direction;
  st.training.state = info.can_train ? TrainingState::Idle : TrainingState::Unavailable;
  st.training.learning_rate = config.adam.learning_rate;
  st.training.timestep = s.volume_options.raw.timestep.value_or(0);
  if (info.can_train && s.train) st.training.state = TrainingState::Running;
  st.version = 1;
  initial = st;
  compute_histogram();
}

ViewerEngine::ViewerEngine(const ViewerSetup& setup) : impl_(std::make_unique<Impl>()) {
  impl_->open(setup);
  impl_->thread = std::thread([this] { impl_->thread_main(); });
}

ViewerEngine::~ViewerEngine() { stop(); }

void ViewerEngine::stop() {
  Impl& m = *impl_;
  {
    std::lock_guard<std::mutex> lock(m.mu);
    m.stopping = true;
  }
  m.halting = true;
  if (TrainingSession* s = m.run.active.load()) s->request_stop();
  m.wake_cv.notify_all();
  if (m.thread.joinable()) m.thread.join();
  {
    std::lock_guard<std::mutex> lock(m.mu);
    m.stopped = true;
  }
  m.frame_cv.notify_all();
}

// ---- the engine thread ----------------------------------------------------------------------------

bool ViewerEngine::Impl::has_work_locked() const {
  return pending_reset || pending_timestep || state.training.state == TrainingState::Running ||
         complete_epoch != epoch;
}

void ViewerEngine::Impl::thread_main() {
  for (;;) {
    ViewerSnapshot snap;
    {
      std::unique_lock<std::mutex> lock(mu);
      wake_cv.wait(lock, [&] { return stopping || has_work_locked(); });
      if (stopping) break;
      snap.state = state;
      snap.interacting = interacting;
      snap.cursor = cursor;
      snap.epoch = epoch;
      snap.tf_epoch = tf_epoch;
      snap.options_epoch = options_epoch;
      snap.reset = pending_reset;
      snap.reset_learning_rate = pending_learning_rate;
      snap.timestep = pending_timestep;
      pending_timestep.reset();
    }
    iterate(snap);
  }
}

// One pass of the loop: pending requests, a training budget, one frame of every unfinished view.
void ViewerEngine::Impl::iterate(const ViewerSnapshot& snap) {
  auto frame = std::make_shared<ViewerFrame>();
  bool rendered = false;
  {
    std::lock_guard<std::mutex> work(work_mu);
    // The cache's decoding thread reads the model: it stops before anything changes the model.
    const bool model_changes = snap.reset || snap.timestep || snap.state.training.state == TrainingState::Running;
    if (model_changes && net_content.cache) net_content.cache->set_asynchronous(false);
    try {
      if (snap.reset) apply_reset(snap.reset_learning_rate);
      if (snap.timestep) load_timestep(*snap.timestep);
    } catch (const std::exception& e) {
      record_error(e.what(), true);
    }
    if (snap.state.training.state == TrainingState::Running && !snap.reset) frame->train_seconds = train_chunk(snap);
    frame->step = run.steps();
    const auto t0 = Clock::now();
    try {
      if (!halting) rendered = render(snap, &frame->refined, &frame->accumulated);
      frame->render_seconds = std::chrono::duration<double>(Clock::now() - t0).count();
      if (rendered) last_render_seconds = frame->render_seconds;
      if (net_content.cache) {
        const BrickCacheStats cs = net_content.cache->stats();
        frame->cache_bricks = cs.resident, frame->cache_stale = cs.stale, frame->cache_pending = cs.requested;
      }
      // A new layout (or any change) shows at once, even when its images were already complete.
      if (!halting && !rendered && snap.epoch != published_epoch) {
        frame->refined = !snap.interacting;
        frame->accumulated = (snap.state.view.layout == ViewLayout::Truth ? truth_pass : net_pass).count;
        rendered = true;
      }
      if (rendered) {
        published_epoch = snap.epoch;
        frame->images = frame_images(snap);
      }
    } catch (const std::exception& e) {
      record_error(e.what(), false);
      rendered = false;
    }
  }
  std::lock_guard<std::mutex> lock(mu);
  if (!rendered) {
    // Nothing left to render for these settings and this model: sleep until something changes.
    if (snap.epoch == epoch) complete_epoch = epoch;
    return;
  }
  frame->state_version = snap.state.version;
  frame->id = next_frame_id++;
  latest = frame;
  latest_epoch = snap.epoch;
  frame_cv.notify_all();
}

void ViewerEngine::Impl::record_error(const std::string& message, bool pause_training) {
  {
    std::lock_guard<std::mutex> lock(mu);
    state.last_error = message;
    ++state.error_count;
    if (pause_training && state.training.state == TrainingState::Running) state.training.state = TrainingState::Paused;
    complete_epoch = epoch;  // a failing render is not retried until something changes
    ++state.version;
  }
  frame_cv.notify_all();
}

// Under mu: a new state version; image_changed restarts the accumulation and wakes the engine.
void ViewerEngine::Impl::bump_locked(bool image_changed) {
  ++state.version;
  if (image_changed) ++epoch;
}

// ---- reading --------------------------------------------------------------------------------------

const ViewerInfo& ViewerEngine::info() const { return impl_->info; }

ViewerState ViewerEngine::state() const {
  std::lock_guard<std::mutex> lock(impl_->mu);
  return impl_->state;
}

std::shared_ptr<const ViewerFrame> ViewerEngine::wait_frame(uint64_t after_id, double timeout_seconds) const {
  Impl& m = *impl_;
  std::unique_lock<std::mutex> lock(m.mu);
  const auto ready = [&] { return m.stopped || m.stopping || (m.latest && m.latest->id > after_id); };
  if (timeout_seconds > 0) m.frame_cv.wait_for(lock, std::chrono::duration<double>(timeout_seconds), ready);
  if (m.stopped || m.stopping || !m.latest || m.latest->id <= after_id) return nullptr;
  return m.latest;
}

std::vector<float> ViewerEngine::losses(size_t from) const {
  std::lock_guard<std::mutex> lock(impl_->mu);
  const auto& l = impl_->losses;
  if (from >= l.size()) return {};
  return std::vector<float>(l.begin() + std::ptrdiff_t(from), l.end());
}

std::vector<std::array<double, 2>> ViewerEngine::psnr_history() const {
  std::lock_guard<std::mutex> lock(impl_->mu);
  return impl_->psnr;
}

std::vector<uint32_t> ViewerEngine::histogram(int bins) const {
  if (bins < 1 || bins > Impl::kFineBins) fail("histogram bins {} is outside 1..{}", bins, Impl::kFineBins);
  std::lock_guard<std::mutex> lock(impl_->mu);
  std::vector<uint32_t> out(size_t(bins), 0);
  const auto& fine = impl_->fine_histogram;
  for (size_t f = 0; f < fine.size(); ++f) {
    const size_t b = size_t(uint64_t(f) * uint64_t(bins) / fine.size());
    out[b] = uint32_t(std::min<uint64_t>(uint64_t(out[b]) + fine[f], UINT32_MAX));
  }
  return out;
}

// ---- setters --------------------------------------------------------------------------------------

void ViewerEngine::set_camera(const Camera& camera, bool interacting) {
  check_camera(camera);
  Impl& m = *impl_;
  {
    std::lock_guard<std::mutex> lock(m.mu);
    m.state.camera = camera;
    m.interacting = interacting;
    m.bump_locked(true);
  }
  m.wake_cv.notify_all();
}

void ViewerEngine::reset_camera() { set_camera(impl_->initial.camera, false); }

void ViewerEngine::set_cursor(std::optional<std::array<float, 2>> xy) {
  if (xy && !((*xy)[0] >= 0 && (*xy)[0] <= 1 && (*xy)[1] >= 0 && (*xy)[1] <= 1))
    fail("the cursor position ({}, {}) is outside [0, 1]", (*xy)[0], (*xy)[1]);
  std::lock_guard<std::mutex> lock(impl_->mu);
  impl_->cursor = xy;  // read with the next frame's snapshot; no image changes
}

void ViewerEngine::set_viewport(int width, int height) {
  if (width < 16 || width > 4096) fail("viewport width {} is outside 16..4096", width);
  if (height < 16 || height > 4096) fail("viewport height {} is outside 16..4096", height);
  Impl& m = *impl_;
  {
    std::lock_guard<std::mutex> lock(m.mu);
    if (m.state.width == width && m.state.height == height) return;
    m.state.width = width;
    m.state.height = height;
    ++m.options_epoch;
    m.bump_locked(true);
  }
  m.wake_cv.notify_all();
}

void ViewerEngine::set_view(const ViewSettings& view) {
  Impl& m = *impl_;
  if (view.layout != ViewLayout::Network && !m.info.has_volume)
    fail("this layout needs a volume (the input is a model without a ground truth): use the network layout");
  if (!(view.split >= 0 && view.split <= 1)) fail("split {} is outside [0, 1]", view.split);
  if (view.slice_axis < 0 || view.slice_axis > 2) fail("slice axis {} is not 0, 1 or 2", view.slice_axis);
  if (!(view.slice_position >= 0 && view.slice_position <= 1))
    fail("slice position {} is outside [0, 1]", view.slice_position);
  {
    std::lock_guard<std::mutex> lock(m.mu);
    m.state.view = view;
    m.bump_locked(true);
  }
  m.wake_cv.notify_all();
}

void ViewerEngine::set_tf(const ViewerTf& tf) {
  check_viewer_tf(tf);
  Impl& m = *impl_;
  {
    std::lock_guard<std::mutex> lock(m.mu);
    m.state.tf = tf;
    ++m.tf_epoch;
    m.bump_locked(true);
  }
  m.wake_cv.notify_all();
}

void ViewerEngine::set_render(const ViewerRender& r) {
  Impl& m = *impl_;
  const RenderSettings& s = r.settings;
  // Interactive limits beyond RenderSettings' own checks (validate: the names and values vnr renders).
  if (!(std::isfinite(s.step) && s.step >= 0.01f && s.step <= 64)) fail("step {} is outside [0.01, 64] voxels", s.step);
  if (!(std::isfinite(s.density) && s.density > 0 && s.density <= 1000)) fail("density {} is outside (0, 1000]", s.density);
  s.validate();
  if (r.max_frames < 0 || r.max_frames > 65536) fail("max_frames {} is outside 0..65536", r.max_frames);
  if (r.coarse_scale < 1 || r.coarse_scale > 16) fail("coarse_scale {} is outside 1..16", r.coarse_scale);
  const Vec3f light = s.light.value_or(viewer_default_light());
  if (!(length(light) > 0)) fail("light direction (0, 0, 0) has no direction");
  const MacroCellMode cells = parse_macrocell_mode(s.macrocells.empty() ? "online" : s.macrocells);
  if (cells == MacroCellMode::Grid && !m.info.has_volume)
    fail("macrocells grid needs the ground-truth volume (use online or off)");
  if (cells == MacroCellMode::Online && !m.online_available)
    fail("macrocells online needs a model trained by vnr or training (use grid or off)");
  ViewerRender checked = r;
  checked.settings.light = normalize(light);
  checked.settings.macrocells = macrocell_mode_name(cells);
  {
    std::lock_guard<std::mutex> lock(m.mu);
    m.state.render = checked;
    ++m.options_epoch;
    m.bump_locked(true);
  }
  m.wake_cv.notify_all();
}

// ---- training -------------------------------------------------------------------------------------

namespace {
void require_training(const ViewerInfo& info) {
  if (!info.can_train)
    fail("training needs the volume: this input is a model without a ground truth (pass one with --ground-truth)");
}
}  // namespace

void ViewerEngine::start_training() {
  Impl& m = *impl_;
  require_training(m.info);
  {
    std::lock_guard<std::mutex> lock(m.mu);
    if (m.state.training.state == TrainingState::Running) return;
    m.state.training.state = TrainingState::Running;
    m.bump_locked(false);
  }
  m.wake_cv.notify_all();
}

void ViewerEngine::pause_training() {
  Impl& m = *impl_;
  require_training(m.info);
  std::lock_guard<std::mutex> lock(m.mu);
  if (m.state.training.state != TrainingState::Running) return;
  m.state.training.state = TrainingState::Paused;
  m.bump_locked(false);
}

void ViewerEngine::reset_training(std::optional<double> learning_rate) {
  Impl& m = *impl_;
  require_training(m.info);
  if (learning_rate && !(std::isfinite(*learning_rate) && *learning_rate > 0 && *learning_rate <= 1))
    fail("learning rate {} is outside (0, 1]", *learning_rate);
  {
    std::lock_guard<std::mutex> lock(m.mu);
    m.pending_reset = true;
    m.pending_learning_rate = learning_rate;
    ViewerTraining& t = m.state.training;
    t.state = TrainingState::Idle;
    t.step = 0;
    t.loss = 0;
    t.samples_per_second = t.seconds = t.psnr = 0;
    if (learning_rate) t.learning_rate = *learning_rate;
    t.n_losses = 0;
    m.losses.clear();
    m.psnr.clear();
    m.bump_locked(true);
  }
  m.wake_cv.notify_all();
}

void ViewerEngine::set_training_budget(double seconds_per_frame) {
  if (!(std::isfinite(seconds_per_frame) && (seconds_per_frame == 0 || (seconds_per_frame >= 0.001 && seconds_per_frame <= 10))))
    fail("training budget {} s is outside 0.001..10 s per frame (0 = auto)", seconds_per_frame);
  std::lock_guard<std::mutex> lock(impl_->mu);
  impl_->state.training.budget_seconds = seconds_per_frame;
  impl_->bump_locked(false);
}

void ViewerEngine::set_timestep(int t) {
  Impl& m = *impl_;
  if (t < 0 || t >= m.info.n_timesteps) fail("timestep {} is outside 0..{}", t, m.info.n_timesteps - 1);
  {
    std::lock_guard<std::mutex> lock(m.mu);
    m.state.training.timestep = t;
    m.pending_timestep = t;
    m.bump_locked(true);
  }
  m.wake_cv.notify_all();
}

void ViewerEngine::set_continuous(bool on, int64_t switch_every) {
  Impl& m = *impl_;
  if (switch_every < 1 || switch_every > 100000000) fail("switch_every {} is outside 1..100000000 steps", switch_every);
  if (on) require_training(m.info);
  if (on && m.info.n_timesteps < 2) fail("continuous training needs a series (the input has one timestep)");
  std::lock_guard<std::mutex> lock(m.mu);
  m.state.training.continuous = on;
  m.state.training.switch_every = switch_every;
  m.bump_locked(false);
}

std::string ViewerEngine::save_model(const std::string& name) { return impl_->save(name); }

Image ViewerEngine::screenshot(double timeout_seconds) {
  Impl& m = *impl_;
  const auto deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                           std::chrono::duration<double>(std::max(0.0, timeout_seconds)));
  // The main image of a refined frame of the settings as they are now: the network's, else the truth's.
  const auto main = [&]() -> const ViewerImage* {
    if (!m.latest || !m.latest->refined || m.latest_epoch != m.epoch) return nullptr;
    const ViewerImage* truth = nullptr;
    for (const ViewerImage& im : m.latest->images) {
      if (im.view == "network") return &im;
      if (im.view == "truth") truth = &im;
    }
    return truth;
  };
  std::shared_ptr<const ViewerFrame> frame;  // kept: the conversion runs without the lock
  const ViewerImage* shown = nullptr;
  bool stopping = false;
  {
    std::unique_lock<std::mutex> lock(m.mu);
    m.frame_cv.wait_until(lock, deadline, [&] { return m.stopping || main(); });
    shown = main();
    frame = m.latest;
    stopping = m.stopping;
  }
  if (!shown) fail("no refined frame within {} s{}", timeout_seconds, stopping ? " (the engine is stopped)" : "");
  return image_of_rgba8(shown->rgba.data(), shown->width, shown->height);
}

}  // namespace vnr
