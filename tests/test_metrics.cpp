#include <gtest/gtest.h>
#include <cmath>
#include <vector>
#include "vnr/metrics.h"
#include "vnr/core/parallel.h"
#include "vnr/core/rng.h"

using namespace vnr;

namespace {

std::vector<float> random_volume(Int3 d, uint64_t seed) {
  Pcg32 rng(seed);
  std::vector<float> v(d.count());
  for (auto& x : v) x = rng.next_float();
  return v;
}

// docs/semantics.md B.4 written out directly: every window, two-pass mean / (n-1) covariance.
double ssim_brute(const std::vector<float>& a, const std::vector<float>& b, Int3 d) {
  const int64_t w[3] = {std::min<int64_t>(7, d.x), std::min<int64_t>(7, d.y), std::min<int64_t>(7, d.z)};
  const double c1 = 1e-4, c2 = 9e-4;
  double total = 0;
  int64_t count = 0;
  for (int64_t z0 = 0; z0 + w[2] <= d.z; ++z0)
    for (int64_t y0 = 0; y0 + w[1] <= d.y; ++y0)
      for (int64_t x0 = 0; x0 + w[0] <= d.x; ++x0) {
        std::vector<double> va, vb;
        for (int64_t z = z0; z < z0 + w[2]; ++z)
          for (int64_t y = y0; y < y0 + w[1]; ++y)
            for (int64_t x = x0; x < x0 + w[0]; ++x) {
              va.push_back(a[size_t(x + d.x * (y + d.y * z))]);
              vb.push_back(b[size_t(x + d.x * (y + d.y * z))]);
            }
        double n = double(va.size()), ma = 0, mb = 0;
        for (size_t i = 0; i < va.size(); ++i) ma += va[i], mb += vb[i];
        ma /= n;
        mb /= n;
        double sa = 0, sb = 0, sab = 0;
        for (size_t i = 0; i < va.size(); ++i) {
          sa += (va[i] - ma) * (va[i] - ma);
          sb += (vb[i] - mb) * (vb[i] - mb);
          sab += (va[i] - ma) * (vb[i] - mb);
        }
        double k = n > 1 ? 1 / (n - 1) : 0;
        total += (2 * ma * mb + c1) * (2 * sab * k + c2) / ((ma * ma + mb * mb + c1) * (sa * k + sb * k + c2));
        ++count;
      }
  return total / double(count);
}

}  // namespace

TEST(Metrics, IdenticalVolumes) {
  Int3 d{12, 10, 9};
  auto a = random_volume(d, 1);
  ErrorStats s = error_stats(a.data(), a.data(), d);
  EXPECT_EQ(s.mse, 0);
  EXPECT_EQ(s.psnr, 999);
  EXPECT_EQ(s.max_abs_error, 0);
  EXPECT_NEAR(ssim3d(a.data(), a.data(), d), 1.0, 1e-12);
}

TEST(Metrics, ConstantOffsetGivesKnownMse) {
  Int3 d{8, 5, 3};
  std::vector<float> a(d.count()), b(d.count());
  for (size_t i = 0; i < a.size(); ++i) {
    a[i] = float(i % 7) / 8;
    b[i] = a[i] + 0.125f;  // every value and difference exactly representable
  }
  ErrorStats s = error_stats(a.data(), b.data(), d);
  EXPECT_NEAR(s.mse, 0.125 * 0.125, 1e-12);
  EXPECT_NEAR(s.psnr, 10 * std::log10(1 / (0.125 * 0.125)), 1e-9);  // 18.0618 dB
  EXPECT_NEAR(s.max_abs_error, 0.125, 1e-7);
  // One differing voxel: mse = e^2 / n.
  std::vector<float> c = a;
  c[17] += 0.5f;
  ErrorStats s1 = error_stats(a.data(), c.data(), d);
  EXPECT_NEAR(s1.mse, 0.25 / double(d.count()), 1e-9);
  EXPECT_NEAR(s1.max_abs_error, 0.5, 1e-7);
}

TEST(Metrics, SsimOfConstantVolumesByHand) {
  // Constant windows: variances and covariance vanish, SSIM = (2ab + C1)/(a^2 + b^2 + C1).
  Int3 d{9, 8, 7};
  std::vector<float> a(d.count(), 0.25f), b(d.count(), 0.5f);
  double c1 = 1e-4;
  EXPECT_NEAR(ssim3d(a.data(), b.data(), d), (2 * 0.125 + c1) / (0.0625 + 0.25 + c1), 1e-12);
}

TEST(Metrics, SsimMatchesBruteForce) {
  Int3 d{12, 10, 9};
  auto a = random_volume(d, 3);
  auto b = a;
  Pcg32 rng(9);
  for (auto& x : b) x = std::min(1.f, std::max(0.f, x + 0.2f * (rng.next_float() - 0.5f)));
  double fast = ssim3d(a.data(), b.data(), d), brute = ssim_brute(a, b, d);
  EXPECT_NEAR(fast, brute, 1e-10);
  EXPECT_LT(fast, 0.99);
  EXPECT_GT(fast, 0.3);
  // Uncorrelated volumes score far lower.
  auto c = random_volume(d, 4);
  EXPECT_NEAR(ssim3d(a.data(), c.data(), d), ssim_brute(a, c, d), 1e-10);
  EXPECT_LT(ssim3d(a.data(), c.data(), d), 0.2);
}

TEST(Metrics, SsimSmallAxesUseWholeAxis) {
  for (Int3 d : {Int3{5, 10, 3}, Int3{7, 7, 7}, Int3{1, 1, 1}, Int3{2, 9, 1}}) {
    auto a = random_volume(d, 5), b = random_volume(d, 6);
    for (size_t i = 0; i < a.size(); ++i) b[i] = 0.5f * a[i] + 0.5f * b[i];
    EXPECT_NEAR(ssim3d(a.data(), b.data(), d), ssim_brute(a, b, d), 1e-10)
        << d.x << "x" << d.y << "x" << d.z;
  }
}

TEST(Metrics, SsimIndependentOfThreadCount) {
  Int3 d{20, 150, 140};  // more than one 64x64 tile of windows in y and z
  auto a = random_volume(d, 7), b = random_volume(d, 8);
  int saved = num_threads();
  set_num_threads(1);
  double one = ssim3d(a.data(), b.data(), d);
  set_num_threads(3);
  double three = ssim3d(a.data(), b.data(), d);
  set_num_threads(saved);
  EXPECT_EQ(one, three);
  EXPECT_NEAR(one, ssim_brute(a, b, d), 1e-10);
}

