#pragma once
// --target-psnr P without --target-ratio (docs/COMPRESSION.md, "Quality target"): the smallest compact
// model that reaches P. Candidates are compact files of volume bytes / R for R = 1024, 512, ..., 4; held-back
// PSNR grows with the model at equal training, so bisection finds the smallest that reaches P after
// about log2(9) ≈ 4 trainings, each of the full `steps` (or `seconds`).
#include <functional>
#include <memory>
#include <optional>
#include "vnr/json.h"
#include "vnr/train/session.h"

namespace vnr {

struct PsnrSearch {
  std::unique_ptr<TrainingSession> session;  // the chosen model, quantized: finish() evaluates and saves it
  bool reached = false;                      // its held-back PSNR reaches the target
  bool interrupted = false;                  // a stop was requested: the search ended early
  Json tried = Json::array();                // every candidate: ratio, bytes, held-back PSNR, steps, seconds
};

// The ratios tried, smallest model first.
std::vector<double> psnr_search_ratios();

// Opens one candidate's session for a setup (open_training_session over a file or a volume in memory).
using SessionOpener = std::function<std::unique_ptr<TrainingSession>(const TrainingSetup&)>;

// setup.target_psnr > 0 and setup.target_ratio == 0. before_training(session) runs before each candidate
// trains (front ends attach their progress and stop handling there); a stop requested in a candidate ends
// the search with the best candidate so far (or that one). When no candidate reaches the target, the
// largest is returned with reached = false.
PsnrSearch search_size_for_psnr(const TrainingSetup& setup, int64_t steps, double seconds, const SessionOpener& open,
                                const MessageFn& message = {},
                                const std::function<void(TrainingSession&)>& before_training = {});

// A setup trained as `vnr train` and vnr.train train it: target_psnr alone searches sizes
// (search_size_for_psnr); otherwise one session from `open`, trained compact (train_compact: quantized,
// its last qat_fraction quantization-aware) when the setup asks for a compact model, else run().
// steps < 0: until `seconds`. before_training(session) runs before each session trains. The caller then
// finish()es the session.
struct TargetTraining {
  std::unique_ptr<TrainingSession> session;
  std::optional<PsnrSearch> search;  // target_psnr alone: the search (its session moved to `session`)
  Json compact;                      // one compact session: train_compact's summary (null otherwise)
};
TargetTraining train_for_targets(const TrainingSetup& setup, int64_t steps, double seconds, const SessionOpener& open,
                                 const MessageFn& message = {},
                                 const std::function<void(TrainingSession&)>& before_training = {});

}  // namespace vnr
