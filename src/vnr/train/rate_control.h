#pragma once
// Compact storage of a trained model (issue 29, docs/COMPRESSION.md): quantization steps per MLP
// matrix and grid level chosen by rate-distortion on held-back samples, quantization-aware training
// (straight-through) over the last part of a run, and the exact byte budget of --target-ratio or the
// quality floor of --target-psnr.
#include <cstdint>
#include <functional>
#include <string>
#include <vector>
#include "vnr/error.h"
#include "vnr/json.h"
#include "vnr/training_options.h"
#include "vnr/nn/network.h"
#include "vnr/nn/param_codec.h"
#include "vnr/train/evaluate.h"
#include "vnr/train/model.h"
#include "vnr/train/sampler.h"

namespace vnr {

class TrainingSession;

// Held-back samples from the training sampler, drawn under a seed that training never uses.
struct ProbeSet {
  std::vector<float> x, y, z, target;
  double mse(const Network& net) const;
};
ProbeSet draw_probe(const Sampler& sampler, int64_t n, uint64_t seed);
// The held-back probe's seed for a training seed: one that training never draws with.
uint64_t probe_seed(uint64_t training_seed);
// Random voxels of a volume in memory at their centres, with their exact values: what the final
// evaluation measures (sampler targets are interpolated between voxels and read ~1 dB optimistic).
ProbeSet draw_voxel_probe(const Volume& vol, int64_t n, uint64_t seed);

// Per-segment steps step_i = g * shape_i. With a_i the growth of the probe MSE per squared step of
// segment i, equal slopes of distortion against rate give shape_i = sqrt(n_i / a_i) (high-rate model:
// D_i = a_i step^2, R_i = n_i (h_i - log2 step)); floor_i keeps |q| <= 1023: a segment whose step
// would fall under it is stored as plain fp16 (step 0).
struct QuantPlan {
  std::vector<ParamSegment> segments;  // counts (steps unset)
  std::vector<double> shape, floor;
  std::vector<ParamSegment> at(double g) const;
};
QuantPlan plan_quantization(Network& net, const ProbeSet& probe);

// Sets the network's parameters (and its fp16 grid copy) to `master` quantized with `segments`:
// exactly the values a model file written with those segments returns.
void apply_quantization(Network& net, const std::vector<float>& master, const std::vector<ParamSegment>& segments);

// fit_bytes' refusal: the budget is below the header and macro-cells alone. Searches over sizes (the
// --target-psnr search, `vnr bench rd`) count it as a size that cannot be made, not as a failure.
class BudgetBelowSmallestFile : public Error {
public:
  using Error::Error;
};

// The scale g whose file (model written with plan.at(g)) is at most target_bytes and as close to it
// as the search finds; `bytes` receives that size. Fails when even the coarsest quantization is larger.
double fit_bytes(const Model& model, const std::vector<float>& master, const QuantPlan& plan, uint64_t target_bytes,
                 uint64_t* bytes);

// Runs the session `steps` steps (or `seconds`), the last qat_fraction of them quantization-aware,
// then leaves model().param_segments and quantized parameters that meet the target, so that
// session.finish() saves and evaluates the compact model. Returns a summary for the report (its
// heldback_psnr below o.target_psnr is for the caller to report).
Json train_compact(TrainingSession& session, int64_t steps, double seconds, const CompactOptions& options,
                   const std::function<void(const std::string&)>& message = {});
// The second half of train_compact: quantizes the session's model for `options`, first training
// qat_steps steps (-1: no limit) or qat_seconds quantization-aware when both are not 0 and the
// trainer allows it. TrainingSession::finish() calls it (no QAT) for a compact session that was only
// run(), so that every front end writes a file that meets the target.
Json compact_session(TrainingSession& session, const CompactOptions& options, int64_t qat_steps, double qat_seconds,
                     const std::function<void(const std::string&)>& message = {});

// Post-training quantization of a model outside a session (a time series' per-timestep models): its
// network's parameters are quantized for o's targets (QAT needs a session) and model.param_segments set,
// so that save_model writes the compact file. Returns the summary compact_session reports.
Json quantize_model(Model& model, const ProbeSet& probe, const CompactOptions& o);

}  // namespace vnr
