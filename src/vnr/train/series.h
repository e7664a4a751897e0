#pragma once
// Time-varying volumes (paper, appendix "Adaptivity with Time-Varying Data").
//
// Two ways to train a series of timesteps, both CLI-free:
//
//  * train_series: one model per timestep. The first timestep trains from the network it is given
//    (normally freshly initialised); each following one starts from the previous timestep's
//    parameters (warm start) with a fresh optimizer (fresh Adam moments and, if the config has one,
//    a restarted learning-rate schedule) and the same step/second budget.
//
//  * train_continuous: the paper's experiment. ONE network and ONE Adam for the whole run, the
//    learning rate fixed (the config's ExponentialDecay removed), never reset; the sampler's
//    target timestep advances every `switch_every` steps. After each switch it measures how many
//    steps the network takes to recover.
//
// Recovery, precisely. A *probe* is a fixed set P of voxels chosen once per run (`probe_voxels`,
// default 2^16, drawn uniformly with replacement by pcg32 from the seed; every voxel in x-fastest
// order when the volume has no more voxels than that). probe PSNR(net, t) = 10 log10(1 / MSE) over
// P between the network decoded at the voxel centres (as `evaluate` decodes them) and timestep t's
// normalised voxel values (999 when the MSE is 0). Probes are taken at the start of every window
// (0 steps after the switch), every `probe_every` steps after it, and after the window's last step.
// For the switch from timestep a to timestep b at global step S (S steps done on earlier windows):
//   psnr_before = probe PSNR(net, a) after step S (the last step trained on a),
//   psnr_after  = probe PSNR(net, b) after step S (same parameters, new target),
//   recovery_steps = the smallest s in {0, probe_every, 2 probe_every, ..., switch_every} such that
//                    probe PSNR(net, b) after step S + s >= psnr_before - recovery_tolerance_db
//                    (so it is exact to the probe interval, and 0 when the new timestep is already
//                    fitted as well as the old one was), or -1 ("not recovered") when no probe of
//                    the window reaches it.
//   recovery_seconds = training time (steps only: no probes, loading or evaluation) from the switch
//                      to that probe.
#include <cstdint>
#include <functional>
#include <string>
#include <vector>
#include "vnr/device.h"
#include "vnr/series.h"
#include "vnr/json.h"
#include "vnr/cuda/cuda.h"
#include "vnr/train/model_io.h"
#include "vnr/train/rate_control.h"
#include "vnr/train/residuals.h"
#include "vnr/train/sampler.h"
#include "vnr/train/session.h"
#include "vnr/train/trainer.h"
#include "vnr/volume/volume.h"

namespace vnr {

// ---------------------------------------------------------------------------------------------
// One model per timestep, warm-started.

// Trains `model` through the selected timesteps. On entry model.net holds the first timestep's
// starting parameters. After each timestep, model.{dims, source_dtype, lo, hi, training,
// macrocells} describe it and `done(result, model)` is called (save the model there: the network
// keeps changing afterwards). A failure (e.g. a frame that cannot be loaded) propagates after the
// `done` calls of every timestep finished before it.
std::vector<TimestepResult> train_series(Model& model, const std::vector<int>& timesteps, const FrameLoader& load,
                                         const SeriesOptions& opts, const SeriesHooks& hooks = {},
                                         const std::function<void(const TimestepResult&, const Model&)>& done = {});

// ---------------------------------------------------------------------------------------------
// Continuous training across timesteps.

// A sampler that forwards to an InCoreSampler whose grid can be switched between steps (not during
// one): what train_continuous trains through.
class SwitchableSampler : public Sampler {
public:
  explicit SwitchableSampler(GridView g = {}) : inner_(g) {}
  void set_target(GridView g) { inner_ = InCoreSampler(g); }
  void begin_step(uint64_t step) override { inner_.begin_step(step); }
  void sample(uint64_t seed, uint64_t step, uint64_t chunk, int n, float* x, float* y, float* z,
              float* target) const override {
    inner_.sample(seed, step, chunk, n, x, y, z, target);
  }

private:
  InCoreSampler inner_;
};

class Decoder;

// The probe PSNR of the header comment: a fixed voxel subset of a grid of `dims`.
class PsnrProbe {
public:
  PsnrProbe(Int3 dims, int64_t n_voxels, uint64_t seed);
  double psnr(const Network& net, const Volume& vol) const;  // vol.dims must equal dims
  // The same with the voxels decoded by `decoder` (a GPU decoder of a trainer's own parameters).
  double psnr(Decoder& decoder, const Volume& vol) const;
  int64_t size() const { return int64_t(index_.size()); }
  const std::vector<int64_t>& voxels() const { return index_; }

private:
  double psnr_of_out(const Volume& vol) const;  // of out_, the decoded voxels, against vol

  Int3 dims_;
  std::vector<int64_t> index_;
  mutable std::vector<float> out_;
};

// `config` with the ExponentialDecay wrapper removed (a constant learning rate) and, when
// learning_rate > 0, Adam's learning rate replaced. The result is in canonical form.
ModelConfig fixed_learning_rate_config(ModelConfig config, float learning_rate = 0);

// The recovery rule of the header comment on the probes of one window: `probes` holds the probes of
// the new timestep, in step order (probes before `switch_step`, the global step of the switch, are
// ignored). Returns the steps from the switch to the first probe with psnr >= threshold, or -1.
int64_t steps_to_recover(const std::vector<ProbePoint>& probes, int64_t switch_step, double threshold);

// Trains model.net continuously over the selected timesteps (in order), `switch_every` steps each.
// model.net is first replaced by a network of fixed_learning_rate_config(its config,
// opts.learning_rate) with the same parameters. After each window, model.{dims, source_dtype, lo,
// hi, training, macrocells} describe that timestep and `done(window, model)` is called (save the
// model there). Frames are loaded when their window starts (at most two in memory; loading is not
// counted in any timing).
ContinuousResult train_continuous(Model& model, const std::vector<int>& timesteps, const FrameLoader& load,
                                  const ContinuousOptions& opts, const SeriesHooks& hooks = {},
                                  const std::function<void(const WindowResult&, const Model&)>& done = {});

}  // namespace vnr
