#include "vnr/train/rate_control.h"
#include "vnr/train/rate_term.h"
#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>
#include "vnr/error.h"
#include "vnr/core/half.h"
#include "vnr/core/rng.h"
#include "vnr/nn/mlp_layout.h"
#include "vnr/nn/quantization_hd.h"
#include "vnr/train/residuals.h"
#include "vnr/train/session.h"
#include "vnr/train/step_learning.h"

namespace vnr {
namespace {

constexpr int kProbeChunk = 4096;

// Parameters no output depends on: the padded output rows of the last matrix and, for a grid, the
// columns of the first matrix that see the zero padding. Zeroed, they cost nothing once coded.
void zero_unused(const MlpLayout& m, std::vector<float>& p) {
  const uint32_t last = m.n_hidden;
  std::fill(p.begin() + int64_t(m.offset[last] + uint64_t(m.n_out) * m.cols[last]),
            p.begin() + int64_t(m.offset[last] + m.rows[last] * m.cols[last]), 0.0f);
  if (m.pad_value == 0.0f)
    for (uint64_t r = 0; r < m.rows[0]; ++r)
      for (uint64_t c = m.first_cols; c < m.cols[0]; ++c) p[m.offset[0] + r * m.cols[0] + c] = 0.0f;
}

ModelFile file_of(const Model& model, const std::vector<float>& master, const std::vector<ParamSegment>& segs) {
  ModelFile f = model_file_without_params(model);
  f.params.resize(master.size());
  uint64_t off = 0;
  for (const ParamSegment& s : segs) {
    for (uint64_t i = off; i < off + s.count; ++i) f.params[i] = float_to_half(quantized_value(master[i], s.step));
    off += s.count;
  }
  f.param_segments = segs;
  f.compact_macrocells = true;  // as save_model writes a compact model
  return f;
}

// The largest g whose quantization keeps `psnr` on the probe. Bisection assumes the PSNR falls as g
// grows, which holds for a trained network but not after quantization-aware steps: those tune the
// network to the steps of g_known (0: none), where it may then beat finer steps and even the master
// copy itself. So the search starts from g_known when that reaches the target; when nothing does, the
// better of g_known and the finest scale.
double fit_psnr(Network& net, const std::vector<float>& master, const QuantPlan& plan, const ProbeSet& probe,
                double psnr, double g_known) {
  auto psnr_at = [&](double g) {
    apply_quantization(net, master, plan.at(g));
    return psnr_of_mse(probe.mse(net));
  };
  auto ok = [&](double g) { return psnr_at(g) >= psnr; };
  double lo = 1e-6;  // g such that ok(lo) and !ok(hi)
  const double psnr_known = g_known > 0 ? psnr_at(g_known) : 0;
  if (g_known > 0 && psnr_known >= psnr) {
    lo = g_known;
  } else {
    const double psnr_finest = psnr_at(lo);
    if (psnr_finest < psnr) return g_known > 0 && psnr_known > psnr_finest ? g_known : lo;
  }
  double hi = lo * 4;  // ok(lo) holds
  while (ok(hi) && hi < 1e6) lo = hi, hi *= 4;
  for (int i = 0; i < 14; ++i) {
    const double mid = std::sqrt(lo * hi);
    (ok(mid) ? lo : hi) = mid;
  }
  return lo;
}

// The scale g that meets o's targets for `master`; *bytes gets that file's size. The model's header
// (training record included) must already be as it will be saved.
// g_known: the scale quantization-aware steps trained for (0: none).
double choose_scale(const Model& model, Network& net, const std::vector<float>& master, const QuantPlan& plan,
                    const ProbeSet& probe, const CompactOptions& o, uint64_t* bytes, double g_known = 0) {
  // Aim a little under the budget: the final evaluation's numbers may lengthen the header.
  const uint64_t aim = o.target_bytes - std::min<uint64_t>(o.target_bytes / 50, 256);
  double g = o.target_psnr > 0 ? fit_psnr(net, master, plan, probe, o.target_psnr, g_known) : 0;
  if (o.target_bytes > 0) g = std::max(g, fit_bytes(model, master, plan, aim, bytes));
  *bytes = vnr_file_bytes(file_of(model, master, plan.at(g)));
  return g;
}

// Full-length placeholders for the numbers the final evaluation writes into the header.
void reserve_evaluation_record(Model& model) {
  model.training["psnr"] = 12.345678901234567;
  model.training["ssim"] = 0.12345678901234567;
  // The training time as its longest text, so the planned size never depends on the clock (two runs of
  // the same steps then quantize alike).
  model.training["seconds"] = 1.2345678901234567e-300;
}

// The network's trained parameters ready to quantize: the plan, the master copy (unused entries
// zeroed) and the held-back PSNR before quantization.
struct Quantization {
  QuantPlan plan;
  std::vector<float> master;
  double psnr_before = 0;
};
Quantization start_quantization(Network& net, const ProbeSet& probe) {
  Quantization q;
  q.psnr_before = psnr_of_mse(probe.mse(net));
  q.plan = plan_quantization(net, probe);
  q.master.assign(net.params().begin(), net.params().end());
  zero_unused(net.mlp(), q.master);
  return q;
}

// Quantizes the network with scale g into model (what save_model then writes) and returns the summary
// both front ends report.
Json finish_quantization(Model& model, const Quantization& q, double g, uint64_t bytes, const ProbeSet& probe,
                         int64_t qat_steps) {
  const std::vector<ParamSegment> segs = q.plan.at(g);
  apply_quantization(*model.net, q.master, segs);
  model.param_segments = segs;
  Json steps = Json::array();
  for (const auto& s : segs) steps.push_back(s.step);
  return Json{{"planned_bytes", bytes},
              {"heldback_psnr_unquantized", q.psnr_before},
              {"heldback_psnr", psnr_of_mse(probe.mse(*model.net))},
              {"qat_steps", qat_steps},
              {"steps", steps}};
}

}  // namespace

uint64_t probe_seed(uint64_t training_seed) { return training_seed ^ 0x9e3779b9u; }

ProbeSet draw_probe(const Sampler& sampler, int64_t n, uint64_t seed) {
  ProbeSet p;
  p.x.resize(size_t(n));
  p.y.resize(size_t(n));
  p.z.resize(size_t(n));
  p.target.resize(size_t(n));
  // A step number no training run reaches: these samples are never trained on.
  const uint64_t step = ~uint64_t(0) - 1;
  for (int64_t c = 0; c * kProbeChunk < n; ++c) {
    const int64_t first = c * kProbeChunk;
    const int k = int(std::min<int64_t>(kProbeChunk, n - first));
    sampler.sample(seed, step, uint64_t(c), k, &p.x[first], &p.y[first], &p.z[first], &p.target[first]);
  }
  return p;
}

ProbeSet draw_voxel_probe(const Volume& vol, int64_t n, uint64_t seed) {
  ProbeSet p;
  const uint64_t count = uint64_t(vol.dims.count());
  n = std::min<int64_t>(n, int64_t(count));
  p.x.resize(size_t(n));
  p.y.resize(size_t(n));
  p.z.resize(size_t(n));
  p.target.resize(size_t(n));
  Pcg32 rng(seed);
  for (int64_t i = 0; i < n; ++i) {
    const uint64_t r = (uint64_t(rng.next_uint()) << 32) | rng.next_uint();
    const int64_t v = int64_t(r % count);
    voxel_centre(vol.dims, v, &p.x[i], &p.y[i], &p.z[i]);
    p.target[i] = vol.data[size_t(v)];
  }
  return p;
}

double ProbeSet::mse(const Network& net) const {
  const int64_t n = int64_t(target.size());
  std::vector<float> out(static_cast<size_t>(n));
  net.infer_fn(
      n,
      [&](int64_t first, int64_t count, float* xs, float* ys, float* zs) {
        std::copy_n(&x[first], count, xs);
        std::copy_n(&y[first], count, ys);
        std::copy_n(&z[first], count, zs);
      },
      out.data());
  double sum = 0;
  for (int64_t i = 0; i < n; ++i) {
    const double d = double(out[i]) - target[i];
    sum += d * d;
  }
  return sum / double(std::max<int64_t>(n, 1));
}

std::vector<ParamSegment> QuantPlan::at(double g) const {
  std::vector<ParamSegment> s = segments;
  // A step under the floor needs more than 10-bit indices: that segment is stored as its fp16 values
  // (step 0, exact) rather than at the floor's step, so finer scales never lose quality.
  for (size_t i = 0; i < s.size(); ++i) s[i].step = g * shape[i] >= floor[i] ? float(g * shape[i]) : 0.0f;
  return s;
}

QuantPlan plan_quantization(Network& net, const ProbeSet& probe) {
  QuantPlan plan;
  plan.segments = param_segments(net.config());
  std::vector<float> master(net.params().begin(), net.params().end());
  zero_unused(net.mlp(), master);
  apply_quantization(net, master, plan.segments);  // steps 0: the fp16 values, unused ones zeroed
  const double base = probe.mse(net);
  Pcg32 rng(0x5eed);
  std::vector<float> noise;
  uint64_t off = 0;
  for (const ParamSegment& s : plan.segments) {
    double sq = 0, max_abs = 0;
    for (uint64_t i = off; i < off + s.count; ++i) {
      sq += double(master[i]) * master[i];
      max_abs = std::max(max_abs, double(std::fabs(master[i])));
    }
    const double rms = std::sqrt(sq / double(std::max<uint64_t>(s.count, 1)));
    // Uniform noise of width delta has the variance of quantization with step delta. The draw comes
    // with its negative (an antithetic pair), whose mean growth of the MSE is the curvature term alone:
    // one draw's first-order term can be of either sign, and on a small segment (the output layer: 16
    // live weights) it can hide the curvature and make the segment look free to quantize coarsely.
    const double delta = std::max(0.5 * rms, 1e-6);
    noise.resize(s.count);
    for (float& e : noise) e = float(delta * (rng.next_float() - 0.5));
    double mse_pair = 0;
    for (const float sign : {1.0f, -1.0f}) {
      net.edit_params([&](float* p, size_t) {
        for (uint64_t i = off; i < off + s.count; ++i) p[i] = master[i] + sign * noise[i - off];
      });
      mse_pair += 0.5 * probe.mse(net);
    }
    const double grown = std::max(mse_pair - base, 1e-4 * base + 1e-14);
    net.edit_params([&](float* p, size_t) { std::copy_n(master.data() + off, s.count, p + off); });
    const double a = grown / (delta * delta);
    plan.shape.push_back(std::sqrt(double(s.count) / a));
    plan.floor.push_back(max_abs / kMaxQuantIndex);
    off += s.count;
  }
  return plan;
}

void apply_quantization(Network& net, const std::vector<float>& master, const std::vector<ParamSegment>& segments) {
  uint64_t off = 0;
  for (const ParamSegment& s : segments) off += s.count;
  if (off != net.n_params()) fail("quantization segments cover {} of {} parameters", off, net.n_params());
  net.edit_params([&](float* p, size_t) {
    uint64_t at = 0;
    for (const ParamSegment& s : segments)
      for (const uint64_t end = at + s.count; at < end; ++at) p[at] = quantized_value(master[at], s.step);
  });
}

double fit_bytes(const Model& model, const std::vector<float>& master, const QuantPlan& plan, uint64_t target,
                 uint64_t* bytes_out) {
  auto bytes = [&](double g) { return vnr_file_bytes(file_of(model, master, plan.at(g))); };
  // Bracket: lo too large a file (or the finest plan), hi within the budget.
  double hi = 1e-4;
  uint64_t b_hi = bytes(hi);
  int guard = 0;
  while (b_hi > target) {
    if (++guard > 60) {
      throw BudgetBelowSmallestFile(
          fmt::format("the target of {} bytes is below the smallest file this model can make ({} bytes: header, "
                      "macro-cells and all parameters zero); choose a smaller model or a lower ratio",
                      target, b_hi));
    }
    hi *= 4;
    b_hi = bytes(hi);
  }
  double lo = hi / 4;
  uint64_t b_lo = bytes(lo);
  while (b_lo <= target && lo > 1e-12) {
    hi = lo, b_hi = b_lo;
    lo /= 4;
    b_lo = bytes(lo);
  }
  if (b_lo <= target) {  // even the finest quantization fits
    *bytes_out = b_lo;
    return lo;
  }
  for (int i = 0; i < 16 && double(b_hi) < 0.985 * double(target); ++i) {
    const double mid = std::sqrt(lo * hi);
    const uint64_t b = bytes(mid);
    if (b <= target) hi = mid, b_hi = b;
    else lo = mid;
  }
  *bytes_out = b_hi;
  return hi;
}

bool can_train_quantized(TrainingSession& session) {
  const Trainer& trainer = session.trainer();
  return trainer.has_quantized_steps() || (trainer.device() == Device::Cpu && !trainer.asynchronous());
}

// Quantization-aware steps with the segments' steps: each step sees the quantized parameters, its update
// lands on the master copy (straight-through); with rate_weight > 0 the grid's bits under those steps
// join the loss (nn/quantization_hd.h rate_weight_per_loss), their gradient taken on the master copy;
// with a StepLearner the steps train too (written into segs) and the bits of every stepped segment join
// the loss with its multiplier. A trainer with quantized steps of its own (the GPU's) runs them on its
// parameters; the CPU trainer through the session's step hooks and its gradient hook. Returns whether
// the rate term was on.
static bool run_quantized_steps(TrainingSession& session, std::vector<float>& master, std::vector<ParamSegment>& segs,
                                double rate_weight, StepLearner* learner, int64_t steps, double seconds) {
  Trainer& trainer = session.trainer();
  Network& net = session.network();
  const size_t first_grid = make_mlp_layout(net.config()).n_matrices;
  const double per_loss = rate_weight > 0 ? rate_weight_per_loss(rate_weight, master.size()) : 0.0;
  if (trainer.has_quantized_steps()) {
    if (learner) fail("learned quantization steps run on the CPU trainer only");
    trainer.begin_quantized_steps(master, segs, first_grid, per_loss);
    try {
      session.run(steps, seconds);
    } catch (...) {
      trainer.end_quantized_steps(master);
      throw;
    }
    trainer.end_quantized_steps(master);
    return per_loss > 0;
  }
  std::vector<float> shown;
  session.set_step_hooks(
      [&] {
        apply_quantization(net, master, segs);
        shown.assign(net.params().begin(), net.params().end());
      },
      [&] {
        for (size_t i = 0; i < master.size(); ++i) master[i] += net.params()[i] - shown[i];
      });
  const bool rate_aware = (per_loss > 0 || learner) && trainer.set_gradient_hook([&](float* grads) {
    if (learner)
      learner->update(master, segs, grads);
    else
      add_rate_gradient(master, segs, first_grid, per_loss * double(trainer.last_loss()), grads);
  });
  auto unhook = [&] {
    session.set_step_hooks({}, {});
    if (rate_aware) trainer.set_gradient_hook({});
  };
  try {
    session.run(steps, seconds);
  } catch (...) {
    unhook();
    throw;
  }
  unhook();
  return rate_aware;
}

Json train_compact(TrainingSession& session, int64_t steps, double seconds, const CompactOptions& o,
                   const std::function<void(const std::string&)>& message) {
  if (!session.data() || !session.data()->sampler) fail("compact storage needs a session opened on training data");
  if (o.learn_steps && session.trainer().has_quantized_steps())
    fail("learned quantization steps (--learn-steps) run on the CPU trainer only; the GPU trainer keeps the planned "
         "steps: leave it off, or train with --device cpu");
  const double f = can_train_quantized(session) ? std::clamp(o.qat_fraction, 0.0, 1.0) : 0.0;
  const bool by_time = steps < 0 && seconds > 0;
  // --seconds covers every phase: the residuals that fill the file or keep a bound after training get
  // their estimated time off the training (compact_session takes the quantization planning's off the last).
  const Int3 dims = session.data()->dims;
  if (by_time && (o.file_bytes > 0 || session.options().error_bound.active()))
    seconds = std::max(seconds - (o.file_bytes > 0 ? residual_fill_seconds(dims) : residual_bound_seconds(dims)), 0.5 * seconds);
  session.set_budget(steps, seconds);  // both phases: the cool-down ends with the quantization-aware steps
  const int64_t steps1 = by_time ? -1 : int64_t(std::llround(double(steps) * (1 - f)));
  session.run(steps1, by_time ? seconds * (1 - f) : 0);
  if (f > 0 && !session.stop_requested())
    return compact_session(session, o, by_time ? -1 : steps - steps1, by_time ? seconds * f : 0, message);
  return compact_session(session, o, 0, 0, message);
}

Json compact_session(TrainingSession& session, const CompactOptions& o, int64_t qat_steps_planned,
                     double qat_seconds, const std::function<void(const std::string&)>& message) {
  if (!session.data() || !session.data()->sampler) fail("compact storage needs a session opened on training data");
  Network& net = session.network();
  Model& model = session.model();
  const bool qat = (qat_steps_planned != 0 || qat_seconds > 0) && can_train_quantized(session);
  const auto planning_start = std::chrono::steady_clock::now();
  const TrainingData& data = *session.data();
  const uint64_t seed = probe_seed(session.trainer().seed());
  const ProbeSet probe = data.vol ? draw_voxel_probe(*data.vol, o.probe_samples, seed)
                                  : draw_probe(*data.sampler, o.probe_samples, seed);
  session.trainer().download();
  Quantization q = start_quantization(net, probe);
  // The header will hold the training record with the final evaluation: size the file with one.
  uint64_t bytes = 0;
  auto choose = [&](double g_known) {
    session.record();
    reserve_evaluation_record(model);
    return choose_scale(model, net, q.master, q.plan, probe, o, &bytes, g_known);
  };
  double g = choose(0);

  int64_t qat_steps = 0;
  bool rate_aware = false;
  if (qat) {
    if (qat_seconds > 0) {  // the planning counts against a --seconds budget
      const double planning = std::chrono::duration<double>(std::chrono::steady_clock::now() - planning_start).count();
      qat_seconds = std::max(qat_seconds - planning, 0.05 * qat_seconds);
      session.shorten_budget(planning);
    }
    const int64_t before = session.steps_done();
    std::vector<ParamSegment> segs = q.plan.at(g);
    std::optional<StepLearner> learner;
    if (o.learn_steps)  // the bits start at the quantizer's own slope, 2 ln 2 loss / parameters per bit
      learner.emplace(q.master, segs, make_mlp_layout(net.config()).n_matrices, q.plan.floor,
                      rate_weight_per_loss(1, q.master.size()) * double(session.trainer().last_loss()));
    rate_aware = run_quantized_steps(session, q.master, segs, o.rate_weight, learner ? &*learner : nullptr,
                                     qat_steps_planned, qat_seconds);
    if (learner) {  // the learned ratios between the steps; the size search scales them to the budget
      for (size_t k = 0; k < segs.size(); ++k)
        if (segs[k].step > 0) q.plan.shape[k] = double(segs[k].step) / g;
      if (message)
        message(fmt::format("learned steps: multiplier {:.3g} per bit, {:.0f} bits against {:.0f} planned",
                            learner->lambda(), learner->bits(), learner->target_bits()));
    }
    qat_steps = session.steps_done() - before;
    zero_unused(net.mlp(), q.master);
    g = choose(g);  // the weights moved a little: meet the target again
  }
  Json summary = finish_quantization(model, q, g, bytes, probe, qat_steps);
  summary["rate_weight"] = rate_aware ? o.rate_weight : 0.0;
  session.freeze_parameters();
  const double psnr_after = summary["heldback_psnr"].get<double>();
  if (message)
    message(fmt::format("compact storage: {} bytes planned, held-back PSNR {:.2f} dB before quantization, {:.2f} dB "
                        "after ({} quantization-aware steps{})",
                        bytes, q.psnr_before, psnr_after, qat_steps,
                        can_train_quantized(session) ? "" : "; not on this trainer"));
  return session.note_compact(summary);
}

Json quantize_model(Model& model, const ProbeSet& probe, const CompactOptions& o) {
  const Quantization q = start_quantization(*model.net, probe);
  const Json record = model.training;
  reserve_evaluation_record(model);
  uint64_t bytes = 0;
  const double g = choose_scale(model, *model.net, q.master, q.plan, probe, o, &bytes);
  model.training = record;
  return finish_quantization(model, q, g, bytes, probe, 0);
}

}  // namespace vnr
