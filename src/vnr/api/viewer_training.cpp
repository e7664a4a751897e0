// ViewerEngine's training run: the session over the current timestep, budgeted chunks of steps, the
// PSNR probe, resets, timestep switches (continuous training) and saving the model.
#include <algorithm>
#include <chrono>
#include <cmath>
#include "vnr/api/viewer_impl.h"
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/train/make_trainer.h"

namespace vnr {

namespace {

constexpr int kOnlineCellSize = 16;
constexpr int64_t kProbeVoxels = int64_t(1) << 16;
constexpr uint64_t kProbeSeed = 0x5eed;
// A probe at most every this many training seconds and steps (both must have passed).
constexpr double kProbeEverySeconds = 0.5;
constexpr int64_t kProbeEverySteps = 50;
// A training budget is run in slices of at most this long, so pause/reset/stop take effect soon.
constexpr double kSliceSeconds = 0.05;
// The automatic budget (budget_seconds = 0): training gets 1.4x the time the last frame took to render
// (docs/VIEWER.md: about half the machine with 10 frames/s on 2 cores), on the CPU at least 30 ms. Not on
// the GPU: a step takes under a millisecond there and a frame a few, so that floor alone would hold the
// viewer under 33 frames/s.
constexpr double kAutoBudgetFactor = 1.4, kAutoBudgetMinCpu = 0.03;
// samples_per_second averages the steps of about the last this many training seconds.
constexpr double kRateWindowSeconds = 1.0;

}  // namespace

// A trainer over the current volume. A series trains through a SwitchableSampler, so a new timestep
// keeps the optimizer (on the GPU that host sampler feeds the GPU trainer); one volume on the GPU is
// sampled from the GPU's own copy.
void ViewerEngine::Impl::create_session() {
  Network& net = *model->net;
  TrainOptions to{setup.batch, setup.seed};
  std::shared_ptr<Sampler> sampler;
  const Volume* in_memory = nullptr;
  if (train_device == Device::Cuda && info.n_timesteps < 2) {
    sampler = std::make_shared<InCoreSampler>(*volume);
    in_memory = volume.get();
  } else {
    if (train_device == Device::Cpu) to.precision = resolve_training_precision("auto", net);
    run.sampler = std::make_shared<SwitchableSampler>(view_of(*volume));
    sampler = run.sampler;
  }
  run.active = nullptr;
  run.session = make_training_session(*model, sampler, in_memory, train_device, to, kOnlineCellSize, SessionOptions{});
  run.active = run.session.get();
  run.losses_published = 0;
  if (!run.probe) run.probe.emplace(volume->dims, kProbeVoxels, kProbeSeed);
}

// Fresh parameters (a model input: its own), step 0, every history cleared.
void ViewerEngine::Impl::apply_reset(std::optional<double> learning_rate) {
  {
    std::lock_guard<std::mutex> lock(mu);
    pending_reset = false;
    pending_learning_rate.reset();
  }
  // Whatever renders the old network goes first: it refers to it.
  net_pass.backend.reset();
  net_content = ViewContent{};
  slices = SliceCache{};
  run.probe_decoder.reset();
  run.active = nullptr;
  run.session.reset();
  if (learning_rate) config.adam.learning_rate = float(*learning_rate);
  auto net = std::make_unique<Network>(config);
  if (input.model) {
    net->set_params(initial_params.data(), initial_params.size());
  } else {
    net->init_params(setup.seed);
    model->macrocells.reset();
  }
  net->set_inference_precision(inference);
  model->net = std::move(net);
  run.step_base = 0;
  run.seconds_base = 0;
  run.probe_step = -1;
  run.probe_seconds = 0;
  run.new_psnr.clear();
  run.continuous = false;
  create_session();
  ++model_version;
  std::lock_guard<std::mutex> lock(mu);
  state.training.learning_rate = config.adam.learning_rate;
  ++state.version;
}

// Loads timestep t of the series and makes it the truth and the training target.
void ViewerEngine::Impl::load_timestep(int t) {
  if (!volume || info.n_timesteps < 2) return;
  VolumeOpenOptions o = setup.volume_options;
  o.raw.timestep = t;
  auto next = std::make_unique<Volume>(open_volume(setup.input, o));
  if (!(next->dims == volume->dims)) fail("timestep {} has other dims than timestep 0", t);
  truth_pass.backend.reset();
  truth_content = ViewContent{};
  grid_ranges.reset();
  grid_ranges_version = ~uint64_t(0);
  slices = SliceCache{};
  if (run.sampler) {
    run.sampler->set_target(view_of(*next));
  } else if (run.session) {
    run.step_base += run.session->steps_done();
    run.seconds_base += run.session->training_seconds();
    run.active = nullptr;
    run.session.reset();
  }
  volume = std::move(next);
  if (!run.session && info.can_train) create_session();
  model->lo = volume->lo;
  model->hi = volume->hi;
  ++volume_version;
  if (run.continuous) run.switch_at = run.steps() + run.switch_every;
  compute_histogram();
  std::lock_guard<std::mutex> lock(mu);
  state.training.timestep = t;
  ++epoch;
  ++state.version;
}

void ViewerEngine::Impl::take_probe() {
  TrainingSession& s = *run.session;
  double psnr = 0;
  s.run_side_work([&] {
    // On the GPU the probe's voxels are decoded there from the trainer's half parameters, device to device,
    // where a download of every parameter and a CPU decode held up a frame every second.
    if (s.trainer().device_half_params()) {
      psnr = run.probe->psnr(current_decoder(run.probe_decoder, Device::Cuda), *volume);
    } else {
      s.trainer().download();
      psnr = run.probe->psnr(*model->net, *volume);
    }
  });
  run.probe_step = run.steps();
  run.probe_seconds = run.seconds();
  run.new_psnr.push_back({double(run.probe_step), psnr});
}

// slot's decoder on `device` of the network with the trainer's current parameters: a GPU decoder takes a
// GPU trainer's device to device; otherwise they come to the host and the decoder is made anew.
Decoder& ViewerEngine::Impl::current_decoder(std::unique_ptr<Decoder>& slot, Device device) {
  const void* half = run.session ? run.session->trainer().device_half_params() : nullptr;
  if (!slot || !slot->reload_device_params(half)) {
    if (run.session) run.session->trainer().download();  // a new decoder copies the host's parameters
    slot = std::make_unique<Decoder>(*model->net, device);
  }
  return *slot;
}

// Trains for the snapshot's budget (at least one step), switching timesteps in continuous mode; an
// error pauses training and lands in state.last_error. Returns the training seconds.
double ViewerEngine::Impl::train_chunk(const ViewerSnapshot& snap) {
  if (!run.session) return 0;
  const ViewerTraining& want = snap.state.training;
  if (want.continuous != run.continuous || (want.continuous && want.switch_every != run.switch_every)) {
    run.continuous = want.continuous;
    run.switch_every = want.switch_every;
    run.switch_at = run.steps() + run.switch_every;
  }
  const double t0 = run.seconds();
  const double min_budget = train_device == Device::Cuda ? 0.0 : kAutoBudgetMinCpu;
  const double budget = want.budget_seconds > 0 ? want.budget_seconds : std::max(min_budget, kAutoBudgetFactor * last_render_seconds);
  try {
    if (run.probe_step < 0) take_probe();
    // Whole steps, the nearest count to the budget plus what earlier chunks left over or overdrew, at
    // least one: a step of a large batch is a good part of a budget, and rounding alone would keep
    // training below it (1.3 budgets of steps always gave one) or swing between one and two.
    const TrainingSession& s = *run.session;
    const double step_seconds = s.steps_done() > 0 ? s.training_seconds() / double(s.steps_done()) : 0;
    const double allowance = budget + run.budget_carry;
    double spent = 0;
    do {
      int64_t limit = -1;
      if (run.continuous) limit = std::max<int64_t>(1, run.switch_at - run.steps());
      if (step_seconds > 0) {
        const int64_t fit = std::max<int64_t>(1, std::llround((allowance - spent) / step_seconds));
        limit = limit < 0 ? fit : std::min(limit, fit);
      }
      run.session->run(limit, std::clamp(allowance - spent, 1e-3, kSliceSeconds));
      spent = run.seconds() - t0;
      if (run.continuous && run.steps() >= run.switch_at) {
        load_timestep((snap.state.training.timestep + 1) % info.n_timesteps);
        break;
      }
    } while (spent + 0.5 * step_seconds <= allowance && keep_training());
    run.budget_carry = step_seconds > 0 ? std::clamp(allowance - spent, -step_seconds, step_seconds) : 0;
    if (run.steps() - run.probe_step >= kProbeEverySteps && run.seconds() - run.probe_seconds >= kProbeEverySeconds)
      take_probe();
  } catch (const std::exception& e) {
    record_error(e.what(), true);
  }
  ++model_version;
  publish_training();
  return run.seconds() - t0;
}

bool ViewerEngine::Impl::keep_training() {
  if (halting) return false;
  std::lock_guard<std::mutex> lock(mu);
  return state.training.state == TrainingState::Running && !pending_reset && !pending_timestep;
}

// The run's progress into the shared state (unless a reset is on its way: that state is already shown).
void ViewerEngine::Impl::publish_training() {
  TrainingSession& s = *run.session;
  const Trainer& trainer = s.trainer();
  // The losses of this chunk's steps alone (the GPU copied all of them every chunk: megabytes a frame
  // after minutes of training).
  const std::vector<float> fresh = trainer.losses_from(run.losses_published);
  run.losses_published += fresh.size();
  // Samples per second over the last steps (about kRateWindowSeconds of them).
  const auto& times = s.step_seconds();
  double window = 0;
  int64_t n = 0;
  for (auto it = times.rbegin(); it != times.rend() && window < kRateWindowSeconds; ++it, ++n) window += *it;
  std::lock_guard<std::mutex> lock(mu);
  if (pending_reset) return;
  losses.insert(losses.end(), fresh.begin(), fresh.end());
  psnr.insert(psnr.end(), run.new_psnr.begin(), run.new_psnr.end());
  run.new_psnr.clear();
  ViewerTraining& t = state.training;
  t.step = run.steps();
  t.loss = s.last_loss();
  t.samples_per_second = window > 0 ? double(n) * double(trainer.batch()) / window : 0;
  t.seconds = run.seconds();
  if (!psnr.empty()) t.psnr = psnr.back()[1];
  t.learning_rate = trainer.current_learning_rate();
  t.n_losses = losses.size();
  ++state.version;
}

namespace {

void check_model_name(const std::string& name) {
  if (name.empty()) fail("the model name is empty");
  if (name.size() > 200) fail("the model name '{}...' is longer than 200 characters", name.substr(0, 40));
  if (name[0] == '.') fail("the model name '{}' starts with '.'", name);
  for (char c : name) {
    const bool ok = (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '.' ||
                    c == '_' || c == '-';
    if (!ok) fail("the model name '{}' may hold only letters, digits, '.', '_' and '-' (no paths)", name);
  }
}

}  // namespace

// Under work_mu: the engine thread is between steps and frames, so the parameters are whole.
std::string ViewerEngine::Impl::save(const std::string& name) {
  if (setup.save_dir.empty()) fail("saving is off: start the viewer with a save directory (--save-dir)");
  check_model_name(name);
  const std::string file = extension_of(name) == ".vnr" ? name : name + ".vnr";
  const std::string path = join_path(setup.save_dir, file);
  std::lock_guard<std::mutex> work(work_mu);
  if (run.session) run.session->save(path);
  else vnr::save_model(path, *model);
  return path;
}

}  // namespace vnr
