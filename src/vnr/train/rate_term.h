#pragma once
// The rate term of rate-aware training (docs/COMPRESSION.md, "Rate-aware training"): the bits a
// parameter costs when quantized with its segment's step under a zero-mean Laplace prior, relaxed to
// a differentiable function of the continuous parameter (the probability mass of the quantization bin
// around it, as training with uniform noise sees it), and its gradient added to the training gradient.
#include <cstdint>
#include <vector>
#include "vnr/nn/param_codec.h"
#include "vnr/nn/quantization_hd.h"  // laplace_bin_bits, laplace_scale

namespace vnr {

// weight * d(total bits)/d(master) added to grads for the segments with a step (grid levels only,
// from `first_segment` on); each segment's Laplace scale is its mean |parameter| (the prior's maximum
// likelihood fit, refitted at every call). Returns the total bits of `master` under that model.
double add_rate_gradient(const std::vector<float>& master, const std::vector<ParamSegment>& segments,
                         size_t first_segment, double weight, float* grads);

// One segment of n parameters quantized with `step` (> 0): its bits under the Laplace prior; with
// grads, weight * d bits/d theta is added to them, and with step_derivatives the bits' derivative by the
// step and the loss's, the straight-through estimate of LSQ (Esser et al. 2020: the sum of
// dL/dq (round(theta/step) - theta/step)) from grads as they were on entry.
struct SegmentRate {
  double bits = 0, dbits_dstep = 0, dloss_dstep = 0;
};
SegmentRate segment_rate(const float* master, uint64_t n, float step, double weight, float* grads,
                         bool step_derivatives);

}  // namespace vnr
