#include "vnr/train/step_learning.h"
#include <algorithm>
#include <cmath>
#include "vnr/error.h"
#include "vnr/train/rate_term.h"

namespace vnr {

StepLearner::StepLearner(const std::vector<float>& master, const std::vector<ParamSegment>& segments,
                         size_t first_segment, std::vector<double> floor, double lambda)
    : first_(first_segment), floor_(std::move(floor)), m_(segments.size(), 0.0), v_(segments.size(), 0.0),
      lambda_(lambda) {
  if (floor_.size() != segments.size()) fail("StepLearner: {} floors for {} segments", floor_.size(), segments.size());
  uint64_t off = 0;
  for (size_t k = 0; k < segments.size(); ++k) {
    const ParamSegment& seg = segments[k];
    if (k >= first_ && seg.step > 0)
      target_ += segment_rate(master.data() + off, seg.count, seg.step, 0, nullptr, false).bits;
    off += seg.count;
  }
  bits_ = target_;
}

void StepLearner::update(const std::vector<float>& master, std::vector<ParamSegment>& segments, float* grads) {
  ++t_;
  constexpr double kBeta1 = 0.9, kBeta2 = 0.999, kEps = 1e-12;
  const double c1 = 1 - std::pow(kBeta1, double(t_)), c2 = 1 - std::pow(kBeta2, double(t_));
  uint64_t off = 0;
  bits_ = 0;
  for (size_t k = 0; k < segments.size(); ++k) {
    ParamSegment& seg = segments[k];
    const uint64_t begin = off;
    off += seg.count;
    if (k < first_ || seg.step <= 0 || seg.count == 0) continue;
    const SegmentRate r = segment_rate(master.data() + begin, seg.count, seg.step, lambda_, grads + begin, true);
    bits_ += r.bits;
    const double g = double(seg.step) * (r.dloss_dstep + lambda_ * r.dbits_dstep);  // d/d log step
    m_[k] = kBeta1 * m_[k] + (1 - kBeta1) * g;
    v_[k] = kBeta2 * v_[k] + (1 - kBeta2) * g * g;
    const double log_step = std::log(double(seg.step)) - kLearningRate * (m_[k] / c1) / (std::sqrt(v_[k] / c2) + kEps);
    seg.step = float(std::max(std::exp(log_step), floor_[k]));
  }
  if (target_ > 0) lambda_ *= std::exp(kLambdaRate * (bits_ / target_ - 1));
}

}  // namespace vnr
