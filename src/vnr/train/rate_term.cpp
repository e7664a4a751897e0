#include "vnr/train/rate_term.h"
#include <algorithm>
#include <cmath>
#include "vnr/core/parallel.h"

namespace vnr {

constexpr int64_t kGrain = 16384;

double add_rate_gradient(const std::vector<float>& master, const std::vector<ParamSegment>& segments,
                         size_t first_segment, double weight, float* grads) {
  uint64_t off = 0;
  double bits = 0;
  for (size_t k = 0; k < segments.size(); ++k) {
    const ParamSegment& seg = segments[k];
    const uint64_t begin = off;
    off += seg.count;
    if (k < first_segment || seg.step <= 0 || seg.count == 0) continue;
    double sum_abs = 0;
    for (uint64_t i = begin; i < off; ++i) sum_abs += std::fabs(master[i]);
    const double scale = laplace_scale(sum_abs, seg.count, seg.step);
    std::vector<double> part((seg.count + kGrain - 1) / kGrain, 0.0);  // per range: the sum is deterministic
    parallel_for_range(int64_t(seg.count), kGrain, [&](int64_t b, int64_t e) {
      double local = 0;
      for (int64_t i = begin + b; i < int64_t(begin) + e; ++i) {
        double d;
        local += laplace_bin_bits(master[i], seg.step, scale, &d);
        grads[i] += float(weight * d);
      }
      part[size_t(b / kGrain)] = local;
    });
    for (double p : part) bits += p;
  }
  return bits;
}

}  // namespace vnr
