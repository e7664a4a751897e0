// Time-varying volumes: warm-started per-timestep training and continuous training with switch /
// recovery measurement (see series.h for the definitions).
#include "vnr/train/series.h"
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <set>
#include "vnr/error.h"
#include "vnr/core/parallel.h"
#include "vnr/progress.h"
#include "vnr/train/decoder.h"
#include "vnr/core/rng.h"
#include "vnr/model_config.h"
#include "vnr/train/make_trainer.h"
#include "vnr/train/session.h"

namespace vnr {
namespace {

using Clock = std::chrono::steady_clock;

// Whole non-negative decimal number, or -1.
int64_t parse_index(const std::string& s) {
  if (s.empty() || s.size() > 12) return -1;
  int64_t v = 0;
  for (char c : s) {
    if (c < '0' || c > '9') return -1;
    v = v * 10 + (c - '0');
  }
  return v;
}

std::string trim(const std::string& s) {
  size_t b = s.find_first_not_of(" \t"), e = s.find_last_not_of(" \t");
  return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
}

Volume load_checked(const FrameLoader& load, int t, const Int3* dims, double* seconds) {
  auto t0 = Clock::now();
  Volume v = load(t);
  *seconds = seconds_since(t0);
  if (dims && !(v.dims == *dims))
    fail("timestep {} has dims {}x{}x{}, but the series' first timestep has {}x{}x{}", t, v.dims.x, v.dims.y, v.dims.z,
         dims->x, dims->y, dims->z);
  return v;
}

void describe_model(Model& model, const Volume& vol) {
  model.dims = vol.dims;
  model.source_dtype = vol.source_dtype;
  model.lo = vol.lo;
  model.hi = vol.hi;
}

}  // namespace

std::vector<int> parse_timestep_selection(const std::string& spec_in, int n_timesteps) {
  const std::string spec = trim(spec_in);
  if (n_timesteps <= 0) fail("the series has no timesteps");
  auto bad = [&]() -> std::vector<int> {
    fail("--timesteps expects all, A-B, A,B,C or a mix such as 0-2,5 (timesteps 0..{}), got '{}'", n_timesteps - 1,
         spec_in);
  };
  std::vector<int> out;
  if (spec == "all") {
    for (int t = 0; t < n_timesteps; ++t) out.push_back(t);
    return out;
  }
  if (spec.empty()) bad();
  std::set<int> seen;
  auto add = [&](int64_t t) {
    if (t >= n_timesteps)
      fail("timestep {} out of range: the series has {} timestep{} (0..{})", t, n_timesteps,
           n_timesteps == 1 ? "" : "s", n_timesteps - 1);
    if (!seen.insert(int(t)).second) fail("--timesteps lists timestep {} twice ('{}')", t, spec_in);
    out.push_back(int(t));
  };
  size_t pos = 0;
  while (pos <= spec.size()) {
    size_t comma = spec.find(',', pos);
    std::string item = trim(spec.substr(pos, comma == std::string::npos ? std::string::npos : comma - pos));
    size_t dash = item.find('-');
    if (dash == std::string::npos) {
      int64_t t = parse_index(item);
      if (t < 0) bad();
      add(t);
    } else {
      int64_t a = parse_index(trim(item.substr(0, dash))), b = parse_index(trim(item.substr(dash + 1)));
      if (a < 0 || b < 0) bad();
      if (b < a) fail("--timesteps range {}-{} is descending (write A-B with A <= B)", a, b);
      if (b >= n_timesteps) add(b);  // the out-of-range message names the bad end
      for (int64_t t = a; t <= b; ++t) add(t);
    }
    if (comma == std::string::npos) break;
    pos = comma + 1;
  }
  return out;
}

std::string timestep_model_name(int timestep, const std::string& extension) {
  return fmt::format("t{:04d}{}", timestep, extension);
}

// ---------------------------------------------------------------------------------------------

std::vector<TimestepResult> train_series(Model& model, const std::vector<int>& timesteps, const FrameLoader& load,
                                         const SeriesOptions& opts, const SeriesHooks& hooks,
                                         const std::function<void(const TimestepResult&, const Model&)>& done) {
  if (!model.net) fail("train_series: the model has no network");
  if (timesteps.empty()) fail("train_series: no timesteps selected");
  if (opts.steps < 0 && !(opts.seconds > 0)) fail("train_series: give a step count or a time limit per timestep");
  if (opts.macrocell_size < 0) fail("macro-cell size must be 0 (none) or positive, got {}", opts.macrocell_size);
  Network& net = *model.net;
  std::vector<TimestepResult> results;
  Int3 dims{};
  for (size_t i = 0; i < timesteps.size(); ++i) {
    const int t = timesteps[i];
    TimestepResult r;
    r.timestep = t;
    Volume vol = load_checked(load, t, i ? &dims : nullptr, &r.load_seconds);
    if (i == 0) dims = vol.dims;
    if (hooks.on_loaded) hooks.on_loaded(t, r.load_seconds);
    r.lo = vol.lo;
    r.hi = vol.hi;
    r.warm_started = opts.warm_start && i > 0;
    if (!opts.warm_start && i > 0) net.init_params(opts.init_seed);

    // A fresh trainer: fresh Adam state and learning-rate schedule, step counter from 0.
    TrainOptions to = opts.train;
    to.seed = opts.train.seed + uint32_t(i);
    SessionOptions so;
    so.cooldown = opts.cooldown;
    so.divergence_message = [t](int64_t step, float loss) {
      return fmt::format("training diverged at step {} of timestep {} (loss {}); try a smaller learning rate", step,
                         t, loss);
    };
    const std::unique_ptr<TrainingSession> owned = make_training_session(
        model, std::make_shared<InCoreSampler>(vol), &vol, opts.device, to, opts.macrocell_size, so, opts.mlp);
    TrainingSession& session = *owned;
    Trainer& trainer = session.trainer();
    const int64_t budget = r.warm_started && opts.warm_steps >= 0 ? opts.warm_steps : opts.steps;
    session.add_step_callback([&](const TrainingProgress& p) {
      if (hooks.on_step) hooks.on_step(t, p.step, p.loss);
      if (hooks.stop && hooks.stop()) session.request_stop();
    });
    session.set_budget(budget, opts.seconds);
    r.steps = session.run(budget, opts.seconds);
    r.interrupted = session.stop_requested();
    r.seconds = session.training_seconds();
    r.final_loss = session.last_loss();
    r.loss_history = trainer.losses();
    trainer.download();  // the GPU's parameters into net (a no-op on the CPU)

    describe_model(model, vol);
    model.training = {{"steps", r.steps},         {"seconds", r.seconds},         {"interrupted", r.interrupted},
                      {"batch", to.batch},        {"seed", to.seed},              {"final_loss", r.final_loss},
                      {"threads", num_threads()}, {"timestep", t},                {"series_index", i},
                      {"warm_start", r.warm_started}, {"continuous", false}};
    model.macrocells.reset();
    if (trainer.has_online_ranges()) model.macrocells = trainer.online_ranges();
    // The saved model may be quantized and carry residuals; the next timestep warm-starts from the
    // trained parameters, not from those.
    const std::vector<float> trained(net.params().begin(), net.params().end());
    if (opts.compact.enabled())
      r.compact = quantize_model(model, draw_voxel_probe(vol, opts.compact.probe_samples, probe_seed(to.seed)),
                                 opts.compact);
    if (opts.error_bound.active()) r.error_bound = attach_error_bound(model, vol, opts.error_bound);
    r.eval = evaluate(net, vol, opts.ssim, Device::Cpu, model.residuals ? &*model.residuals : nullptr);
    model.training["psnr"] = r.eval.psnr;
    if (opts.ssim) model.training["ssim"] = r.eval.ssim;
    results.push_back(r);
    if (done) done(results.back(), model);
    if (!model.param_segments.empty() || model.residuals) {
      net.set_params(trained.data(), trained.size());
      model.param_segments.clear();
      model.residuals.reset();
    }
    if (r.interrupted) break;
  }
  return results;
}

// ---------------------------------------------------------------------------------------------

PsnrProbe::PsnrProbe(Int3 dims, int64_t n_voxels, uint64_t seed) : dims_(dims) {
  const int64_t total = int64_t(dims.count());
  if (total <= 0) fail("PsnrProbe: empty volume");
  if (n_voxels <= 0) fail("the PSNR probe needs at least one voxel, got {}", n_voxels);
  if (n_voxels >= total) {
    index_.resize(size_t(total));
    for (int64_t i = 0; i < total; ++i) index_[size_t(i)] = i;
  } else {
    index_.resize(size_t(n_voxels));
    Pcg32 rng(seed * 0x9E3779B97F4A7C15ULL + 0x243F6A8885A308D3ULL, 0x9b);
    const uint64_t n = uint64_t(total);
    for (auto& v : index_) {
      // 64 random bits, reduced without a measurable bias for any realistic voxel count.
      uint64_t r = (uint64_t(rng.next_uint()) << 32) | rng.next_uint();
      v = int64_t(r % n);
    }
  }
  out_.resize(index_.size());
}

double PsnrProbe::psnr(const Network& net, const Volume& vol) const {
  decode_voxels(net, dims_, index_.data(), int64_t(index_.size()), out_.data());
  return psnr_of_out(vol);
}

double PsnrProbe::psnr(Decoder& decoder, const Volume& vol) const {
  decoder.voxels(dims_, index_.data(), int64_t(index_.size()), out_.data());
  return psnr_of_out(vol);
}

double PsnrProbe::psnr_of_out(const Volume& vol) const {
  if (!(vol.dims == dims_))
    fail("PsnrProbe: volume dims {}x{}x{} differ from the probe's {}x{}x{}", vol.dims.x, vol.dims.y, vol.dims.z,
         dims_.x, dims_.y, dims_.z);
  double se = 0;
  for (size_t i = 0; i < index_.size(); ++i) {
    double d = double(out_[i]) - double(vol.data[size_t(index_[i])]);
    se += d * d;
  }
  const double mse = se / double(index_.size());
  return mse > 0 ? 10 * std::log10(1 / mse) : 999.0;
}

ModelConfig fixed_learning_rate_config(ModelConfig c, float learning_rate) {
  c.decay.enabled = false;
  if (learning_rate > 0) c.adam.learning_rate = learning_rate;
  else if (learning_rate < 0 || !std::isfinite(learning_rate)) fail("the learning rate must be positive, got {}", learning_rate);
  return c;
}

int64_t steps_to_recover(const std::vector<ProbePoint>& probes, int64_t switch_step, double threshold) {
  for (const ProbePoint& p : probes)
    if (p.step >= switch_step && p.psnr >= threshold) return p.step - switch_step;
  return -1;
}

namespace {

void check_continuous(const Model& model, const std::vector<int>& timesteps, const ContinuousOptions& opts) {
  if (!model.net) fail("train_continuous: the model has no network");
  if (timesteps.empty()) fail("train_continuous: no timesteps selected");
  if (opts.switch_every <= 0) fail("continuous training needs a positive switch interval (steps per timestep), got {}", opts.switch_every);
  if (opts.probe_every <= 0) fail("the probe interval must be positive, got {}", opts.probe_every);
  if (opts.macrocell_size < 0) fail("macro-cell size must be 0 (none) or positive, got {}", opts.macrocell_size);
  if (!(opts.recovery_tolerance_db >= 0)) fail("the recovery tolerance must be >= 0 dB, got {}", opts.recovery_tolerance_db);
}

// The recovery of the switch into window w from its probes (`mine`, in step order) and the window's
// training seconds at each of them.
void measure_recovery(WindowResult& w, const std::vector<ProbePoint>& mine, const std::vector<double>& seconds_at,
                      double tolerance_db) {
  w.recovery_steps = steps_to_recover(mine, w.first_step, w.psnr_before - tolerance_db);
  if (w.recovery_steps >= 0)
    for (size_t i = 0; i < mine.size(); ++i)
      if (mine[i].step - w.first_step == w.recovery_steps) {
        w.recovery_seconds = seconds_at[i];
        break;
      }
}

// model.{dims, source_dtype, lo, hi, training, macrocells} after window k.
void describe_window(Model& model, const Volume& cur, const WindowResult& w, size_t k, const ContinuousOptions& opts,
                     float learning_rate, const Trainer& trainer) {
  describe_model(model, cur);
  model.training = {{"steps", w.steps},
                    {"seconds", w.seconds},
                    {"interrupted", w.interrupted},
                    {"batch", opts.train.batch},
                    {"seed", opts.train.seed},
                    {"final_loss", w.final_loss},
                    {"psnr", w.eval.psnr},
                    {"threads", num_threads()},
                    {"timestep", w.timestep},
                    {"series_index", k},
                    {"continuous", true},
                    {"first_step", w.first_step},
                    {"learning_rate", learning_rate}};
  if (opts.ssim) model.training["ssim"] = w.eval.ssim;
  model.macrocells.reset();
  if (trainer.has_online_ranges()) model.macrocells = trainer.online_ranges();
}

}  // namespace

// One function: the windows share the session, the probe and the sampler their side work refers to.
ContinuousResult train_continuous(Model& model, const std::vector<int>& timesteps, const FrameLoader& load,
                                  const ContinuousOptions& opts, const SeriesHooks& hooks,
                                  const std::function<void(const WindowResult&, const Model&)>& done) {
  check_continuous(model, timesteps, opts);
  ContinuousResult res;
  // One network with a constant learning rate, same parameters.
  res.config = fixed_learning_rate_config(model.net->config(), opts.learning_rate);
  {
    auto fixed = std::make_unique<Network>(res.config);
    if (fixed->n_params() != model.net->n_params()) fail("train_continuous: parameter layout changed");  // cannot happen
    fixed->set_params(model.net->params().data(), model.net->params().size());
    model.net = std::move(fixed);
  }
  Network& net = *model.net;
  res.learning_rate = net.config().adam.learning_rate;

  WindowResult first;
  Volume cur = load_checked(load, timesteps[0], nullptr, &first.load_seconds);
  if (hooks.on_loaded) hooks.on_loaded(timesteps[0], first.load_seconds);
  const Int3 dims = cur.dims;
  PsnrProbe probe(dims, opts.probe_voxels, opts.probe_seed);
  res.probe_voxels = probe.size();

  auto sampler = std::make_shared<SwitchableSampler>(view_of(cur));
  // ONE trainer (one optimizer) for the whole run; the session's step loop runs every window.
  int current_timestep = timesteps[0];
  SessionOptions so;
  so.divergence_message = [&](int64_t step, float loss) {
    return fmt::format("training diverged at step {} (timestep {}, loss {}); try a smaller learning rate", step,
                       current_timestep, loss);
  };
  so.sync_every = opts.probe_every;  // a GPU's groups of steps end at every probe
  const std::unique_ptr<TrainingSession> owned =
      make_training_session(model, sampler, nullptr, opts.device, opts.train, 0, so, opts.mlp);
  TrainingSession& session = *owned;
  Trainer& trainer = session.trainer();
  int64_t global = 0;
  double last_probe = 0;  // probe PSNR after the latest step, on the current target
  for (size_t k = 0; k < timesteps.size(); ++k) {
    WindowResult w = k == 0 ? first : WindowResult{};
    w.timestep = timesteps[k];
    w.first_step = global;
    if (k > 0) {
      Volume next = load_checked(load, w.timestep, &dims, &w.load_seconds);
      if (hooks.on_loaded) hooks.on_loaded(w.timestep, w.load_seconds);
      w.has_switch = true;
      w.from_timestep = timesteps[k - 1];
      w.psnr_before = last_probe;  // after the last step on the old timestep
      cur = std::move(next);       // the old frame is released here
      sampler->set_target(view_of(cur));
    }
    w.lo = cur.lo;
    w.hi = cur.hi;
    if (opts.macrocell_size > 0) trainer.enable_online_ranges(dims, opts.macrocell_size);  // (re)starts empty

    const size_t probes_before = res.probes.size();
    double p0 = probe.psnr(net, cur);
    res.probes.push_back({global, w.timestep, p0});
    w.psnr_after = p0;
    std::vector<double> seconds_at;  // training seconds of the window at each of its probes
    seconds_at.push_back(0);
    current_timestep = w.timestep;
    // After every step (side work: the probes are not training time): histories, hooks, the stop poll, probes.
    session.add_side_work([&](const TrainingProgress& p) {
      const int64_t s = p.step - w.first_step;
      w.seconds = p.elapsed;
      if (!std::isfinite(p.loss)) return;  // the session fails with the divergence message
      if (hooks.on_step) hooks.on_step(w.timestep, s, p.loss);
      w.interrupted = hooks.stop && hooks.stop();
      if (s % opts.probe_every == 0 || s == opts.switch_every || w.interrupted) {
        trainer.download();
        res.probes.push_back({p.step, w.timestep, probe.psnr(net, cur)});
        seconds_at.push_back(w.seconds);
      }
      if (w.interrupted) session.request_stop();
    });
    w.steps = session.run(opts.switch_every);
    session.clear_side_work();
    global = session.steps_done();
    // Every step's loss (a GPU runs steps in groups between the side work's calls); the rate is fixed.
    const std::vector<float> losses = trainer.losses();
    res.loss_history.insert(res.loss_history.end(), losses.begin() + std::ptrdiff_t(w.first_step), losses.end());
    res.learning_rate_history.insert(res.learning_rate_history.end(), size_t(w.steps), trainer.current_learning_rate());
    const float loss = session.last_loss();
    last_probe = res.probes.back().psnr;
    w.psnr_end = last_probe;
    w.final_loss = loss;
    if (w.has_switch)
      measure_recovery(w, std::vector<ProbePoint>(res.probes.begin() + std::ptrdiff_t(probes_before), res.probes.end()),
                       seconds_at, opts.recovery_tolerance_db);
    trainer.download();
    w.eval = evaluate(net, cur, opts.ssim);
    describe_window(model, cur, w, k, opts, res.learning_rate, trainer);
    res.windows.push_back(w);
    if (done) done(res.windows.back(), model);
    if (w.interrupted) break;
  }
  return res;
}

}  // namespace vnr
