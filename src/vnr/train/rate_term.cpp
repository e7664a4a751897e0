#include "vnr/train/rate_term.h"
#include <algorithm>
#include <cmath>
#include "vnr/core/parallel.h"

namespace vnr {

constexpr int64_t kGrain = 16384;

SegmentRate segment_rate(const float* master, uint64_t n, float step, double weight, float* grads,
                         bool step_derivatives) {
  double sum_abs = 0;
  for (uint64_t i = 0; i < n; ++i) sum_abs += std::fabs(master[i]);
  const double scale = laplace_scale(sum_abs, n, step);
  std::vector<SegmentRate> part((n + kGrain - 1) / kGrain);  // per range: the sums are deterministic
  parallel_for_range(int64_t(n), kGrain, [&](int64_t b, int64_t e) {
    SegmentRate local;
    for (int64_t i = b; i < e; ++i) {
      double d, dstep = 0;
      local.bits += laplace_bin_bits(master[i], step, scale, &d, step_derivatives ? &dstep : nullptr);
      if (!grads) continue;
      if (step_derivatives) {
        const double u = double(master[i]) / step;
        const double q = std::clamp(std::nearbyint(u), -double(kMaxQuantIndex), double(kMaxQuantIndex));
        // d(q step)/d step: q - u inside the range (round passes gradients straight through), q where clamped
        local.dloss_dstep += double(grads[i]) * (std::fabs(u) <= kMaxQuantIndex ? q - u : q);
        local.dbits_dstep += dstep;
      }
      grads[i] += float(weight * d);
    }
    part[size_t(b / kGrain)] = local;
  });
  SegmentRate total;
  for (const SegmentRate& p : part) {
    total.bits += p.bits;
    total.dbits_dstep += p.dbits_dstep;
    total.dloss_dstep += p.dloss_dstep;
  }
  return total;
}

double add_rate_gradient(const std::vector<float>& master, const std::vector<ParamSegment>& segments,
                         size_t first_segment, double weight, float* grads) {
  uint64_t off = 0;
  double bits = 0;
  for (size_t k = 0; k < segments.size(); ++k) {
    const ParamSegment& seg = segments[k];
    const uint64_t begin = off;
    off += seg.count;
    if (k < first_segment || seg.step <= 0 || seg.count == 0) continue;
    bits += segment_rate(master.data() + begin, seg.count, seg.step, weight, grads + begin, false).bits;
  }
  return bits;
}

}  // namespace vnr
