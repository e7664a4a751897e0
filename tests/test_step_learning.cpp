// Learned quantization steps (train/step_learning.h): the step's rate derivative against finite
// differences, and the learned steps against the closed-form equal-slope optimum of a toy loss.
#include <gtest/gtest.h>
#include <cmath>
#include <vector>
#include <fmt/format.h>
#include "vnr/core/rng.h"
#include "vnr/nn/quantization_hd.h"
#include "vnr/train/rate_term.h"
#include "vnr/train/step_learning.h"

using namespace vnr;

TEST(StepLearning, BinBitsStepDerivativeMatchesFiniteDifferences) {
  for (double step : {0.01, 0.1, 1.0})
    for (double scale : {0.003, 0.05, 2.0})
      for (double theta : {0.0, 0.2 * step, -0.3 * step, 0.45 * step, -0.55 * step, 0.7 * step, 3.2 * step}) {
        SCOPED_TRACE(fmt::format("step {} scale {} theta {}", step, scale, theta));
        const double h = 1e-6 * step;
        double d;
        const double fd = (laplace_bin_bits(theta, step + h, scale, &d) - laplace_bin_bits(theta, step - h, scale, &d)) /
                          (2 * h);
        double dstep = 0;
        laplace_bin_bits(theta, step, scale, &d, &dstep);
        EXPECT_NEAR(dstep, fd, 1e-4 * std::max(1.0, std::fabs(fd)));
      }
}

// Two segments of Laplace-distributed parameters under the loss sum_k w_k |quantized - theta|^2, one 16
// times as sensitive as the other. At high rate, D_k = w_k n s_k^2 / 12 and R_k = n (h - log2 s_k), so the
// stationary point of D + lambda R has s_k^2 proportional to 1 / w_k: the learned steps end at a ratio of
// sqrt(1 / 16) = 0.25, while the multiplier keeps the bits at those of the starting steps.
TEST(StepLearning, StepsReachTheEqualSlopeRatioAtTheStartingBits) {
  const uint64_t n = 2000;
  const double w[2] = {16.0, 1.0};
  std::vector<float> master(2 * n);
  Pcg32 rng(7);
  for (float& v : master) {  // Laplace(0, 0.05) by inversion
    const double u = rng.next_float() - 0.5;
    v = float(-0.05 * (u < 0 ? -1 : 1) * std::log(1 - 2 * std::fabs(u)));
  }
  std::vector<ParamSegment> segs = {{n, 0.01f, {}}, {n, 0.01f, {}}};
  StepLearner learner(master, segs, 0, {1e-6, 1e-6}, 1e-3);
  std::vector<float> grads(master.size());
  for (int it = 0; it < 12000; ++it) {
    for (size_t k = 0; k < 2; ++k)
      for (uint64_t i = k * n; i < (k + 1) * n; ++i) {
        const double s = segs[k].step;
        grads[i] = float(2 * w[k] * (s * std::nearbyint(master[i] / s) - master[i]));
      }
    learner.update(master, segs, grads.data());
  }
  EXPECT_NEAR(segs[0].step / segs[1].step, 0.25, 0.025) << segs[0].step << " " << segs[1].step;
  EXPECT_NEAR(learner.bits() / learner.target_bits(), 1.0, 0.02);
}
