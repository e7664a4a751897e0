// Dispatching MLP kernels vs the scalar reference, on every SIMD target this CPU supports, plus a
// finite-difference check of the gradients of one tiny layer.
#include <gtest/gtest.h>
#include <hwy/targets.h>

#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "vnr/nn/mlp_bf16.h"
#include "vnr/nn/mlp_bf16_train.h"
#include "vnr/nn/mlp_kernels.h"

namespace k = vnr::kernels;

namespace {

constexpr float kRelTol = 1e-5f;

std::vector<float> random_vec(size_t count, std::mt19937& rng, float lo = -1.0f, float hi = 1.0f) {
  std::uniform_real_distribution<float> u(lo, hi);
  std::vector<float> v(count);
  for (float& x : v) x = u(rng);
  return v;
}

std::vector<float> abs_vec(std::vector<float> v) {
  for (float& x : v) x = std::fabs(x);
  return v;
}

// Mask like a ReLU output: ~1/3 exactly 0 (some -0.0f), a few negative, the rest positive.
std::vector<float> random_mask(size_t count, std::mt19937& rng) {
  std::vector<float> m = random_vec(count, rng, 0.01f, 1.0f);
  std::uniform_int_distribution<int> pick(0, 8);
  for (float& x : m) {
    const int p = pick(rng);
    if (p <= 2) x = 0.0f;
    else if (p == 3) x = -0.0f;
    else if (p == 4) x = -x;
  }
  return m;
}

// Runs `body` once per SIMD target compiled in and supported here, with dispatch forced to it.
template <class F>
void for_each_target(F&& body) {
  const std::vector<int64_t> targets = hwy::SupportedAndGeneratedTargets();
  ASSERT_FALSE(targets.empty());
  for (int64_t t : targets) {
    hwy::SetSupportedTargetsForTest(t);
    SCOPED_TRACE(hwy::TargetName(t));
    ASSERT_STREQ(k::simd_target_name(), hwy::TargetName(t));
    body();
  }
  hwy::SetSupportedTargetsForTest(0);
}

const int kDims[] = {1, 3, 8, 16, 17, 32, 64, 80, 128};
const int kNs[] = {16, 32, 128, 256};

void check_fwd(int rows, int cols, int n, bool relu, std::mt19937& rng) {
  SCOPED_TRACE("fwd rows=" + std::to_string(rows) + " cols=" + std::to_string(cols) +
               " n=" + std::to_string(n) + " relu=" + std::to_string(relu));
  const auto W = random_vec(size_t(rows) * cols, rng), X = random_vec(size_t(cols) * n, rng);
  std::vector<float> Y(size_t(rows) * n, 123.0f), pre(Y.size()), scale(Y.size());
  k::matmul_fwd(W.data(), rows, cols, X.data(), Y.data(), n, relu);
  k::ref::matmul_fwd(W.data(), rows, cols, X.data(), pre.data(), n, false);
  // Summation-order error bound scales with sum |w||x|.
  k::ref::matmul_fwd(abs_vec(W).data(), rows, cols, abs_vec(X).data(), scale.data(), n, false);
  int bad = 0;
  for (size_t i = 0; i < Y.size() && bad < 5; ++i) {
    const float tol = kRelTol * scale[i] + 1e-30f;
    const float want = relu ? (pre[i] > 0.0f ? pre[i] : 0.0f) : pre[i];
    if (!(std::fabs(Y[i] - want) <= tol)) {
      ADD_FAILURE() << "i=" << i << " got " << Y[i] << " want " << want;
      ++bad;
    }
    if (relu && pre[i] < -tol && Y[i] != 0.0f) {  // clearly negative pre-activation -> exactly 0
      ADD_FAILURE() << "i=" << i << " relu of " << pre[i] << " gave " << Y[i];
      ++bad;
    }
    if (relu && !(Y[i] >= 0.0f)) ++bad, ADD_FAILURE() << "negative relu output at " << i;
  }
}

void check_bwd_data(int rows, int cols, int n, bool masked, std::mt19937& rng) {
  SCOPED_TRACE("bwd_data rows=" + std::to_string(rows) + " cols=" + std::to_string(cols) +
               " n=" + std::to_string(n) + " masked=" + std::to_string(masked));
  const auto W = random_vec(size_t(rows) * cols, rng), dY = random_vec(size_t(rows) * n, rng);
  const auto mask = random_mask(size_t(cols) * n, rng);
  const float* m = masked ? mask.data() : nullptr;
  std::vector<float> dX(size_t(cols) * n, 123.0f), want(dX.size()), scale(dX.size());
  k::matmul_bwd_data(W.data(), rows, cols, dY.data(), m, dX.data(), n);
  k::ref::matmul_bwd_data(W.data(), rows, cols, dY.data(), m, want.data(), n);
  k::ref::matmul_bwd_data(abs_vec(W).data(), rows, cols, abs_vec(dY).data(), nullptr, scale.data(), n);
  int bad = 0;
  for (size_t i = 0; i < dX.size() && bad < 5; ++i) {
    if (masked && !(mask[i] > 0.0f)) {
      if (dX[i] != 0.0f) ++bad, ADD_FAILURE() << "mask " << mask[i] << " at " << i << " gave " << dX[i];
      continue;
    }
    if (!(std::fabs(dX[i] - want[i]) <= kRelTol * scale[i] + 1e-30f))
      ++bad, ADD_FAILURE() << "i=" << i << " got " << dX[i] << " want " << want[i];
  }
}

void check_bwd_weights(int rows, int cols, int n, std::mt19937& rng) {
  SCOPED_TRACE("bwd_weights rows=" + std::to_string(rows) + " cols=" + std::to_string(cols) +
               " n=" + std::to_string(n));
  const auto dY = random_vec(size_t(rows) * n, rng), X = random_vec(size_t(cols) * n, rng);
  const auto dW0 = random_vec(size_t(rows) * cols, rng);  // non-zero: the kernel must accumulate
  std::vector<float> dW = dW0, want(dW0.size(), 0.0f), scale(dW0.size(), 0.0f);
  k::matmul_bwd_weights(dY.data(), rows, X.data(), cols, n, dW.data());
  k::ref::matmul_bwd_weights(dY.data(), rows, X.data(), cols, n, want.data());
  k::ref::matmul_bwd_weights(abs_vec(dY).data(), rows, abs_vec(X).data(), cols, n, scale.data());
  int bad = 0;
  for (size_t i = 0; i < dW.size() && bad < 5; ++i) {
    const float expect = dW0[i] + want[i];
    const float tol = kRelTol * (scale[i] + std::fabs(dW0[i])) + 1e-30f;
    if (!(std::fabs(dW[i] - expect) <= tol))
      ++bad, ADD_FAILURE() << "i=" << i << " got " << dW[i] << " want " << expect;
  }
}

}  // namespace

TEST(MlpKernels, ChoosesAvx512WhenAvailable) {
  const std::string name = k::simd_target_name();
  std::printf("SIMD target: %s; targets tested:", name.c_str());
  for (int64_t t : hwy::SupportedAndGeneratedTargets()) std::printf(" %s", hwy::TargetName(t));
  std::printf("\n");
  if (hwy::SupportedTargets() & (HWY_AVX3 | HWY_AVX3_DL)) EXPECT_TRUE(name == "AVX3" || name == "AVX3_DL");
}

TEST(MlpKernels, FwdMatchesReference) {
  for_each_target([] {
    std::mt19937 rng(1);
    for (int rows : kDims)
      for (int cols : kDims)
        for (int n : kNs)
          for (bool relu : {false, true}) check_fwd(rows, cols, n, relu, rng);
  });
}

TEST(MlpKernels, BwdDataMatchesReference) {
  for_each_target([] {
    std::mt19937 rng(2);
    for (int rows : kDims)
      for (int cols : kDims)
        for (int n : kNs)
          for (bool masked : {false, true}) check_bwd_data(rows, cols, n, masked, rng);
  });
}

TEST(MlpKernels, BwdWeightsAccumulatesAndMatchesReference) {
  for_each_target([] {
    std::mt19937 rng(3);
    for (int rows : kDims)
      for (int cols : kDims)
        for (int n : kNs) check_bwd_weights(rows, cols, n, rng);
  });
}

// n not a multiple of the vector length is outside the contract but must still be right.
TEST(MlpKernels, OddSampleCountsStillCorrect) {
  std::mt19937 rng(4);
  for (int n : {1, 5, 20, 37}) {
    check_fwd(17, 9, n, true, rng);
    check_bwd_data(9, 17, n, true, rng);
    check_bwd_weights(17, 9, n, rng);
  }
}

TEST(MlpKernels, ReluAndMaskEdgeValues) {
  // W = identity: outputs equal inputs, so the epilogues see hand-picked values.
  const int d = 16, n = 16;
  std::vector<float> W(d * d, 0.0f);
  for (int i = 0; i < d; ++i) W[i * d + i] = 1.0f;
  std::vector<float> X(d * n), Y(d * n), mask(d * n), dX(d * n);
  const float vals[] = {-1.0f, -0.0f, 0.0f, 1e-7f, -1e-7f, 3.0f, -3.0f, 0.5f};
  for (int i = 0; i < d * n; ++i) {
    X[i] = vals[i % 8];
    mask[i] = vals[(i / 3) % 8];
  }
  for_each_target([&] {
    k::matmul_fwd(W.data(), d, d, X.data(), Y.data(), n, true);
    for (int i = 0; i < d * n; ++i) EXPECT_EQ(Y[i], X[i] > 0.0f ? X[i] : 0.0f) << i;
    k::matmul_fwd(W.data(), d, d, X.data(), Y.data(), n, false);
    for (int i = 0; i < d * n; ++i) EXPECT_EQ(Y[i], X[i]) << i;
    k::matmul_bwd_data(W.data(), d, d, X.data(), mask.data(), dX.data(), n);
    for (int i = 0; i < d * n; ++i) EXPECT_EQ(dX[i], mask[i] > 0.0f ? X[i] : 0.0f) << i;
  });
}

// L(W, X0) = sum(G * relu(W relu(X0))). Analytic gradients from the kernels vs central differences
// of L evaluated in double (L is piecewise linear, so away from kinks the difference is exact up to
// rounding).
TEST(MlpKernels, FiniteDifferenceGradients) {
  const int rows = 5, cols = 7, n = 16;
  std::mt19937 rng(5);
  auto W = random_vec(rows * cols, rng);
  auto X0 = random_vec(cols * n, rng);
  const auto G = random_vec(rows * n, rng);
  for (float& x : X0)
    if (std::fabs(x) < 0.1f) x = x < 0 ? -0.1f : 0.1f;  // keep input ReLU away from its kink

  auto loss = [&](const std::vector<float>& w, const std::vector<float>& x0) {
    double L = 0.0;
    for (int r = 0; r < rows; ++r)
      for (int s = 0; s < n; ++s) {
        double pre = 0.0;
        for (int c = 0; c < cols; ++c) pre += double(w[r * cols + c]) * std::max(0.0, double(x0[c * n + s]));
        L += double(G[r * n + s]) * std::max(0.0, pre);
      }
    return L;
  };

  std::vector<float> X(cols * n);
  for (int i = 0; i < cols * n; ++i) X[i] = X0[i] > 0.0f ? X0[i] : 0.0f;
  std::vector<float> Y(rows * n), pre(rows * n);
  k::matmul_fwd(W.data(), rows, cols, X.data(), Y.data(), n, true);
  k::matmul_fwd(W.data(), rows, cols, X.data(), pre.data(), n, false);
  for (float p : pre) ASSERT_GT(std::fabs(p), 1e-3f) << "pre-activation too close to the ReLU kink";
  std::vector<float> dPre(rows * n);
  for (int i = 0; i < rows * n; ++i) dPre[i] = Y[i] > 0.0f ? G[i] : 0.0f;
  std::vector<float> dW(rows * cols, 0.0f), dX0(cols * n);
  k::matmul_bwd_weights(dPre.data(), rows, X.data(), cols, n, dW.data());
  k::matmul_bwd_data(W.data(), rows, cols, dPre.data(), X.data(), dX0.data(), n);

  // Perturb by a power of two small enough not to cross a kink; floats hold w +- h exactly.
  const float h = 1.0f / 4096;
  for (int i = 0; i < rows * cols; ++i) {
    auto wp = W, wm = W;
    wp[i] += h;
    wm[i] -= h;
    const double fd = (loss(wp, X0) - loss(wm, X0)) / (double(wp[i]) - double(wm[i]));
    EXPECT_NEAR(dW[i], fd, 1e-5 * (1.0 + std::fabs(fd))) << "dW " << i;
  }
  for (int i = 0; i < cols * n; ++i) {
    auto xp = X0, xm = X0;
    xp[i] += h;
    xm[i] -= h;
    const double fd = (loss(W, xp) - loss(W, xm)) / (double(xp[i]) - double(xm[i]));
    EXPECT_NEAR(dX0[i], fd, 1e-5 * (1.0 + std::fabs(fd))) << "dX " << i;
    if (X0[i] < 0.0f) EXPECT_EQ(dX0[i], 0.0f) << i;
  }
}

// A leading dimension larger than cols: only the first cols columns of each W row take part.
TEST(MlpKernels, LeadingDimensionSkipsTrailingColumns) {
  const int rows = 16, cols = 8, ldw = 16, n = 32;
  std::vector<float> W(rows * ldw), X(ldw * n), dY(rows * n);
  std::mt19937 gen(4);
  std::uniform_real_distribution<float> U(-1.f, 1.f);
  for (auto& v : W) v = U(gen);
  for (auto& v : X) v = U(gen);
  for (auto& v : dY) v = U(gen);
  std::vector<float> Wc(rows * cols);  // the same weights, compacted
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) Wc[r * cols + c] = W[r * ldw + c];
  std::vector<float> y1(rows * n), y2(rows * n);
  vnr::kernels::matmul_fwd(W.data(), rows, cols, X.data(), y1.data(), n, true, ldw);
  vnr::kernels::ref::matmul_fwd(Wc.data(), rows, cols, X.data(), y2.data(), n, true);
  for (size_t i = 0; i < y1.size(); ++i) EXPECT_NEAR(y1[i], y2[i], 1e-5f);
  std::vector<float> d1(cols * n), d2(cols * n);
  vnr::kernels::matmul_bwd_data(W.data(), rows, cols, dY.data(), nullptr, d1.data(), n, ldw);
  vnr::kernels::ref::matmul_bwd_data(Wc.data(), rows, cols, dY.data(), nullptr, d2.data(), n);
  for (size_t i = 0; i < d1.size(); ++i) EXPECT_NEAR(d1[i], d2[i], 1e-5f);
  std::vector<float> g1(rows * ldw, 7.0f), g2(rows * cols, 7.0f);
  vnr::kernels::matmul_bwd_weights(dY.data(), rows, X.data(), cols, n, g1.data(), ldw);
  vnr::kernels::ref::matmul_bwd_weights(dY.data(), rows, X.data(), cols, n, g2.data());
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < ldw; ++c)
      EXPECT_NEAR(g1[r * ldw + c], c < cols ? g2[r * cols + c] : 7.0f, 1e-4f) << r << "," << c;  // untouched past cols
}

// The fused 16-wide forward equals the layer-by-layer reference (ReLU hidden layers, one output).
TEST(MlpKernels, Fused16WideForwardMatchesLayerByLayer) {
  std::mt19937 gen(8);
  std::uniform_real_distribution<float> U(-0.5f, 0.5f);
  for (int n_hidden : {1, 2, 4}) {
    const int k0 = 8, ldw0 = 16, n = 64;
    std::vector<float> W0(16 * ldw0), Wh(16 * 16 * 4), Wout(16), X(ldw0 * n);
    for (auto* v : {&W0, &Wh, &Wout, &X})
      for (auto& e : *v) e = U(gen);
    std::vector<const float*> hp;
    for (int l = 0; l + 1 < n_hidden; ++l) hp.push_back(Wh.data() + l * 256);
    std::vector<float> fused(n);
    vnr::kernels::mlp_forward_16(W0.data(), k0, ldw0, hp.data(), n_hidden - 1, Wout.data(), X.data(), n, fused.data());
    std::vector<float> a(16 * n), b(16 * n), y(n);
    vnr::kernels::ref::matmul_fwd(W0.data(), 16, k0, X.data(), a.data(), n, true, ldw0);
    for (int l = 0; l + 1 < n_hidden; ++l) {
      vnr::kernels::ref::matmul_fwd(hp[l], 16, 16, a.data(), b.data(), n, true);
      std::swap(a, b);
    }
    vnr::kernels::ref::matmul_fwd(Wout.data(), 1, 16, a.data(), y.data(), n, false);
    for (int s = 0; s < n; ++s) EXPECT_NEAR(fused[s], y[s], 1e-5f) << n_hidden << " " << s;
  }
}

// ---- bf16 inference kernels ----

TEST(MlpBf16, RoundsToNearestEven) {
  EXPECT_EQ(k::to_bf16(1.0f), 0x3f80);
  EXPECT_EQ(k::to_bf16(-2.0f), 0xc000);
  // 1 + 2^-8 lies halfway between 1 and 1 + 2^-7: ties go to the even mantissa (1.0)
  EXPECT_EQ(k::to_bf16(1.0f + 1.0f / 256), 0x3f80);
  EXPECT_EQ(k::to_bf16(1.0f + 3.0f / 256), 0x3f82);  // halfway, odd below: rounds up
  EXPECT_EQ(k::to_bf16(1.0f + 1.0f / 256 + 1.0f / 65536), 0x3f81);
  EXPECT_TRUE(std::isnan(k::from_bf16(k::to_bf16(std::nanf("")))));
  EXPECT_EQ(k::from_bf16(k::to_bf16(0.15625f)), 0.15625f);  // exactly representable
}

// The vector kernels against the double-precision reference on the same bf16 operands: the only
// difference is fp32 accumulation (and, for pairs, one bf16 rounding of a value that may sit on
// the other side of a rounding boundary), bounded relative to the sum of |products|.
TEST(MlpBf16, ForwardMatchesReference) {
  if (!k::bf16_supported()) GTEST_SKIP() << "this CPU has no AVX512-BF16";
  std::mt19937 rng(7);
  for (int rows : {1, 2, 3, 4, 6, 8, 14, 16, 64}) {
    for (int K : {1, 2, 5, 16, 64, 80}) {
      for (int n : {16, 48, 64, 256}) {
        SCOPED_TRACE(testing::Message() << rows << " x " << K << ", n = " << n);
        const int kp = (K + 1) / 2;
        std::vector<float> W = random_vec(size_t(rows) * K, rng), X = random_vec(size_t(K) * n, rng);
        std::vector<uint32_t> Wp(size_t(rows) * kp), Xp(size_t(kp) * n);
        k::weights_to_bf16_pairs(W.data(), rows, K, K, Wp.data());
        k::activations_to_bf16_pairs(X.data(), K, n, Xp.data());
        for (int j = 0; j < kp; ++j)  // the vector conversion equals the scalar rounding
          for (int s = 0; s < n; ++s) {
            const uint32_t p = Xp[size_t(j) * n + s];
            ASSERT_EQ(p & 0xffffu, k::to_bf16(X[size_t(2 * j) * n + s]));
            ASSERT_EQ(p >> 16, 2 * j + 1 < K ? k::to_bf16(X[size_t(2 * j + 1) * n + s]) : 0u);
          }
        // bound on the fp32 accumulation error: K * 2^-24 * sum |products| (<= K for |w|, |x| <= 1)
        const float tol = float(K) * 6e-8f * float(K) + 1e-7f;
        std::vector<float> Y(size_t(rows) * n), Yr(Y.size());
        k::matmul_fwd_bf16_linear(Wp.data(), rows, kp, Xp.data(), Y.data(), n);
        k::ref::matmul_fwd_bf16_linear(Wp.data(), rows, kp, Xp.data(), Yr.data(), n);
        for (size_t i = 0; i < Y.size(); ++i) ASSERT_NEAR(Y[i], Yr[i], tol) << i;
        if (rows % 2) continue;
        std::vector<uint32_t> P(size_t(rows / 2) * n), Pr(P.size());
        k::matmul_fwd_bf16_relu(Wp.data(), rows, kp, Xp.data(), P.data(), n);
        k::ref::matmul_fwd_bf16_relu(Wp.data(), rows, kp, Xp.data(), Pr.data(), n);
        for (size_t i = 0; i < P.size(); ++i)
          for (int h = 0; h < 2; ++h) {
            const float a = k::from_bf16(uint16_t(P[i] >> (16 * h))), b = k::from_bf16(uint16_t(Pr[i] >> (16 * h)));
            ASSERT_GE(a, 0.0f);
            ASSERT_NEAR(a, b, std::fabs(b) / 128 + tol) << i;  // one bf16 ulp
          }
      }
    }
  }
}

// The in-register 16-wide bf16 forward sums its hidden layers in the same order as the layer-by-layer
// bf16 kernels (one accumulator per output, pairs in ascending order), so the hidden activations are
// the same bf16 values; only the output's two accumulator chains round differently (fp32 level).
TEST(MlpBf16, Fused16WideForwardMatchesLayerByLayer) {
  if (!k::bf16_supported()) GTEST_SKIP() << "this CPU has no AVX512-BF16";
  std::mt19937 rng(11);
  for (int k0 : {8, 7, 16}) {
    for (int n_mid : {0, 1, 3}) {
      SCOPED_TRACE(testing::Message() << "k0 = " << k0 << ", " << n_mid << " middle layers");
      const int n = 64, kp0 = (k0 + 1) / 2;
      std::vector<float> W0 = random_vec(size_t(16) * k0, rng), X0 = random_vec(size_t(k0) * n, rng);
      std::vector<uint32_t> W0p(size_t(16) * kp0), Wout(8);
      k::weights_to_bf16_pairs(W0.data(), 16, k0, k0, W0p.data());
      std::vector<std::vector<uint32_t>> Wh(n_mid, std::vector<uint32_t>(16 * 8));
      std::vector<const uint32_t*> whp;
      for (auto& w : Wh) {
        std::vector<float> f = random_vec(16 * 16, rng);
        k::weights_to_bf16_pairs(f.data(), 16, 16, 16, w.data());
        whp.push_back(w.data());
      }
      std::vector<float> wo = random_vec(16, rng);
      k::weights_to_bf16_pairs(wo.data(), 1, 16, 16, Wout.data());
      std::vector<float> fused(n), layered(n);
      k::mlp_forward_16_bf16(W0p.data(), k0, whp.data(), n_mid, Wout.data(), X0.data(), n, fused.data());
      std::vector<uint32_t> P0(size_t(kp0) * n), A(8 * n), B(8 * n);
      k::activations_to_bf16_pairs(X0.data(), k0, n, P0.data());
      k::matmul_fwd_bf16_relu(W0p.data(), 16, kp0, P0.data(), A.data(), n);
      for (int l = 0; l < n_mid; ++l) {
        k::matmul_fwd_bf16_relu(whp[l], 16, 8, A.data(), B.data(), n);
        std::swap(A, B);
      }
      k::matmul_fwd_bf16_linear(Wout.data(), 1, 8, A.data(), layered.data(), n);
      for (int s = 0; s < n; ++s) ASSERT_NEAR(fused[s], layered[s], 1e-5f * (1.0f + std::fabs(layered[s]))) << s;
    }
  }
}

// ---- bf16 training kernels (sample-major, mlp_bf16_train.h) ----

namespace {
std::vector<uint32_t> random_pairs(size_t count, std::mt19937& rng) {
  std::vector<float> f = random_vec(2 * count, rng);
  std::vector<uint32_t> p(count);
  for (size_t i = 0; i < count; ++i) p[i] = k::bf16_pair(f[2 * i], f[2 * i + 1]);
  return p;
}
}  // namespace

// Every epilogue, every V, row counts with every tail, in the two addressing patterns the trainer
// uses (P rows contiguous: forward and data gradient; P columns contiguous: weight gradient).
TEST(MlpBf16Train, PairGemmMatchesReference) {
  if (!k::bf16_supported()) GTEST_SKIP() << "this CPU has no AVX512-BF16";
  std::mt19937 rng(23);
  using Out = k::PairGemmOut;
  for (int V : {1, 2, 4, 8})
    for (int M : {1, 5, 12, 13, 31, 64})
      for (int kp : {1, 8, 33})
        for (bool rows_contiguous : {true, false})
          for (Out out : {Out::ReluBf16, Out::MaskBf16, Out::F32, Out::AddF32, Out::Column}) {
            SCOPED_TRACE(testing::Message() << "V " << V << " M " << M << " kp " << kp << " rows " << rows_contiguous
                                            << " out " << int(out));
            const int L = 16 * V;
            std::vector<uint32_t> P = random_pairs(size_t(M) * kp, rng), Q = random_pairs(size_t(kp) * (L + 3), rng);
            k::PairGemm g;
            g.P = P.data(), g.kp = kp, g.si = rows_contiguous ? kp : 1, g.sk = rows_contiguous ? 1 : M;
            g.Q = Q.data(), g.ldq = L + 3, g.V = V, g.M = M, g.out = out;
            const int valid = L - 5;
            g.valid = valid;
            std::vector<uint16_t> maskv(size_t(M) * L);
            for (uint16_t& m : maskv) m = k::to_bf16(std::uniform_real_distribution<float>(-1, 1)(rng));
            g.mask = maskv.data(), g.mask_ld = L;
            const float tol = float(kp) * 2 * 1.2e-7f * 2 * kp + 1e-7f;  // fp32 sums of 2 kp products |p| <= 1
            if (out == Out::ReluBf16 || out == Out::MaskBf16) {
              std::vector<uint16_t> a(size_t(M) * L + 7, 0x1234), b = a;
              g.dst = a.data(), g.ld = L;
              k::pair_gemm(g);
              g.dst = b.data();
              k::ref::pair_gemm(g);
              for (size_t i = 0; i < a.size(); ++i) {
                const float x = k::from_bf16(a[i]), y = k::from_bf16(b[i]);
                ASSERT_NEAR(x, y, std::fabs(y) / 128 + tol) << i;  // one bf16 ulp
                if (out == Out::ReluBf16 && i < size_t(M) * L) ASSERT_GE(x, 0.0f);
              }
            } else {
              const bool column = out == Out::Column;
              std::vector<float> a = random_vec(column ? size_t(L) * M + 3 : size_t(M) * (L + 2), rng), b = a;
              g.ld = column ? M : L + 2;
              g.dst = a.data();
              k::pair_gemm(g);
              g.dst = b.data();
              k::ref::pair_gemm(g);
              for (size_t i = 0; i < a.size(); ++i) ASSERT_NEAR(a[i], b[i], tol) << i;
            }
          }
}

TEST(MlpBf16Train, LayoutConversionsAreExact) {
  if (!k::bf16_supported()) GTEST_SKIP() << "this CPU has no AVX512-BF16";
  std::mt19937 rng(29);
  for (int K : {1, 7, 8, 16, 31, 33, 64, 100}) {
    SCOPED_TRACE(testing::Message() << "K = " << K);
    const int n = 64, kp = (K + 1) / 2, lda = kp + 2;
    const std::vector<float> X = random_vec(size_t(K) * n, rng);
    std::vector<uint32_t> A(size_t(n) * lda, 0xdeadbeefu);
    k::feature_major_to_sm_pairs(X.data(), K, n, A.data(), lda);
    for (int s = 0; s < n; ++s)
      for (int j = 0; j < lda; ++j) {
        const uint32_t want = j >= kp ? 0xdeadbeefu
                                      : k::bf16_pair(X[size_t(2 * j) * n + s], 2 * j + 1 < K ? X[size_t(2 * j + 1) * n + s] : 0.0f);
        ASSERT_EQ(A[size_t(s) * lda + j], want) << s << " " << j;
      }
    const int ldd = (K + 15) / 16 * 16;
    const std::vector<float> D = random_vec(size_t(n) * ldd, rng);
    std::vector<float> Xb(size_t(K + 1) * n, -7.0f);
    k::sm_to_feature_major(D.data(), ldd, K, n, Xb.data(), n);
    for (int c = 0; c <= K; ++c)
      for (int s = 0; s < n; ++s) ASSERT_EQ(Xb[size_t(c) * n + s], c < K ? D[size_t(s) * ldd + c] : -7.0f);
    // sample pairs of a bf16 row-major matrix (row stride K + 3 words)
    const int lds = ldd, ldw = K + 3;
    std::vector<uint16_t> Aw(size_t(n) * ldw);
    for (uint16_t& w : Aw) w = k::to_bf16(std::uniform_real_distribution<float>(-1, 1)(rng));
    std::vector<uint32_t> S(size_t(n / 2) * lds, 0xdeadbeefu);
    k::sample_pairs(Aw.data(), ldw, K, n, S.data(), lds);
    for (int j = 0; j < n / 2; ++j)
      for (int c = 0; c < lds; ++c) {
        const uint32_t want = c < K ? uint32_t(Aw[size_t(2 * j) * ldw + c]) | uint32_t(Aw[size_t(2 * j + 1) * ldw + c]) << 16 : 0u;
        ASSERT_EQ(S[size_t(j) * lds + c], want) << j << " " << c;
      }
  }
}
