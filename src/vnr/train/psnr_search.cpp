#include "vnr/trainer.h"
#include <cmath>
#include "vnr/error.h"
#include "vnr/train/rate_control.h"

namespace vnr {

std::vector<double> psnr_search_ratios() {
  std::vector<double> r;
  for (double x = 1024; x >= 4; x /= 2) r.push_back(x);
  return r;
}

namespace {

struct Candidate {
  std::unique_ptr<TrainingSession> session;
  double psnr = 0;
  bool reached = false;
};

}  // namespace

PsnrSearch search_size_for_psnr(const TrainingSetup& setup, int64_t steps, double seconds, const SessionOpener& open,
                                const MessageFn& message, const std::function<void(TrainingSession&)>& before_training) {
  if (!(setup.target_psnr > 0)) fail("search_size_for_psnr needs a target PSNR");
  if (setup.target_ratio > 0) fail("--target-psnr with --target-ratio quantizes one model; there is no size to search");
  auto say = [&](const std::string& line) {
    if (message) message(line);
  };
  const std::vector<double> ratios = psnr_search_ratios();
  PsnrSearch out;
  auto train = [&](size_t i) {
    TrainingSetup s = setup;
    s.target_ratio = ratios[i];
    Candidate c;
    c.session = open(s);
    CompactOptions o = c.session->options().compact;
    if (before_training) before_training(*c.session);
    try {
      const Json summary = train_compact(*c.session, steps, seconds, o, message);
      c.psnr = summary["heldback_psnr"].get<double>();
    } catch (const BudgetBelowSmallestFile&) {
      c.psnr = 0;  // a budget below the header and macro-cells of this volume: a size that cannot be made
    }
    c.reached = c.psnr >= setup.target_psnr;
    out.interrupted = c.session->stop_requested();
    out.tried.push_back(Json{{"ratio", ratios[i]},
                             {"target_bytes", o.target_bytes},
                             {"heldback_psnr", c.psnr},
                             {"reached", c.reached},
                             {"steps", c.session->steps_done()},
                             {"seconds", c.session->training_seconds()}});
    say(fmt::format("--target-psnr {}: {}x model ({} bytes) reaches {:.2f} dB on held-back voxels: {}",
                    setup.target_psnr, ratios[i], o.target_bytes, c.psnr, c.reached ? "enough" : "not enough"));
    return c;
  };
  // Bisection for the first index (smallest model) that reaches the target.
  // The largest size (hi's start) is only trained when no smaller one reached the target.
  size_t lo = 0, hi = ratios.size() - 1;
  Candidate best, last;
  while (lo < hi && !out.interrupted) {
    const size_t mid = (lo + hi) / 2;
    last = train(mid);
    if (last.reached) hi = mid, best = std::move(last);
    else lo = mid + 1;
  }
  if (!out.interrupted && !best.session) {
    last = train(lo);
    if (last.reached) best = std::move(last);
  }
  out.reached = best.session != nullptr;
  out.session = out.reached ? std::move(best.session) : std::move(last.session);
  if (!out.reached && !out.interrupted)
    say(fmt::format("warning: --target-psnr {}: no model up to {}x reaches it on held-back voxels ({:.2f} dB at best); "
                    "keeping the largest. Train longer (--steps/--seconds) or give a larger config",
                    setup.target_psnr, ratios.back(), last.psnr));
  return out;
}

TargetTraining train_for_targets(const TrainingSetup& setup, int64_t steps, double seconds, const SessionOpener& open,
                                 const MessageFn& message, const std::function<void(TrainingSession&)>& before_training) {
  TargetTraining t;
  if (setup.target_psnr > 0 && setup.target_ratio <= 0) {
    check_training_setup(setup);
    t.search.emplace(search_size_for_psnr(setup, steps, seconds, open, message, before_training));
    t.session = std::move(t.search->session);
    return t;
  }
  t.session = open(setup);
  if (before_training) before_training(*t.session);
  if (t.session->options().compact.enabled()) {
    t.compact = train_compact(*t.session, steps, seconds, t.session->options().compact, message);
  } else {
    t.session->set_budget(steps, seconds);
    t.session->run(steps, seconds);
  }
  return t;
}

}  // namespace vnr
