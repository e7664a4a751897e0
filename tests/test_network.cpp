// MLP forward/backward, losses, Adam and the training loop against independent references:
// finite differences, closed forms and hand-computed updates.
#include <gtest/gtest.h>
#include <cmath>
#include <atomic>
#include <chrono>
#include <random>
#include <thread>
#include "vnr/nn/loss.h"
#include "vnr/nn/mlp_bf16.h"
#include "vnr/nn/network.h"
#include "vnr/nn/optimizer.h"
#include "vnr/train/model_io.h"
#include "vnr/train/trainer.h"
#include "test_support.h"

using namespace vnr;
using namespace vnr::test;

namespace {
Json small_model(std::string enc = "HashGrid", int width = 16, int hidden = 2, std::string out_act = "None",
                 std::string loss = "L2", std::string act = "ReLU") {
  Json e = enc == "HashGrid" ? Json{{"otype", "HashGrid"},
                                   {"n_levels", 3},
                                   {"n_features_per_level", 2},
                                   {"log2_hashmap_size", 10},
                                   {"base_resolution", 4}}
                             : Json{{"otype", enc}};
  return mlp_model_config(e, width, hidden, act, out_act, loss);
}
}  // namespace

// Objective sum_s G_s * out_s; analytic dW and dX0 from mlp_backward vs central differences.
TEST(Mlp, BackwardMatchesFiniteDifferences) {
  // Hidden "None" is smooth (tight check); ReLU has kinks, so it uses a small step and a looser bound.
  for (std::string hidden_act : {"None", "ReLU"})
  for (std::string act : {"None", "Sigmoid", "Softplus"})
    for (int width : {16, 24}) {
      const bool relu = hidden_act == "ReLU";
      Network net(small_model("Identity", width, 3, act, "L2", hidden_act));
      net.init_params(5);
      const MlpLayout& m = net.mlp();
      std::mt19937 gen(9);
      std::uniform_real_distribution<float> U(-1.f, 1.f);
      net.edit_params([&](float* p, size_t) {
        for (uint64_t i = 0; i < m.n_params; ++i) p[i] = U(gen) * 0.5f;
      });
      const int n = 32;
      std::vector<float> X0(m.in_pad * n), G(n), acts(net.acts_floats(n)), pre(n), out(n), dW(m.n_params, 0.f),
          dX0(m.in_pad * n), scratch(2 * m.width * n);
      for (auto& v : X0) v = U(gen);
      for (auto& g : G) g = U(gen);
      const float h = relu ? 1e-3f : 1e-2f;
      // A ReLU kink inside [x-h, x+h] makes central differences meaningless: detect it by the
      // disagreement of the two one-sided differences and skip that probe.
      auto kinked = [&](double fp, double f0, double fm) {
        return relu && std::fabs((fp - f0) - (f0 - fm)) / h > 1e-3 + 1e-3 * std::fabs((fp - fm) / (2 * h));
      };
      auto objective = [&]() {
        net.mlp_forward(X0.data(), n, acts.data(), pre.data(), out.data());
        double acc = 0;
        for (int s = 0; s < n; ++s) acc += double(out[s]) * G[s];
        return acc;
      };
      objective();
      std::vector<float> dpre(n);
      for (int s = 0; s < n; ++s) dpre[s] = G[s] * activate_derivative(m.output_activation, pre[s]);
      net.mlp_backward(X0.data(), acts.data(), dpre.data(), n, dW.data(), dX0.data(), scratch.data());
      const double tol_abs = relu ? 5e-3 : 1e-3, tol_rel = relu ? 2e-2 : 5e-3;
      std::uniform_int_distribution<uint64_t> pick(0, m.n_params - 1);
      int checked = 0;
      for (int trial = 0; trial < 60; ++trial) {
        uint64_t k = pick(gen);
        // Only rows that reach the output (the padded output rows have no gradient by design).
        if (k >= m.offset[m.n_hidden] + m.n_out * m.width) continue;
        const float keep = net.params()[k];
        auto set = [&](float v) { net.edit_params([&](float* p, size_t) { p[k] = v; }); };
        set(keep + h);
        double fp = objective();
        set(keep - h);
        double fm = objective();
        set(keep);
        if (kinked(fp, objective(), fm)) continue;
        double fd = (fp - fm) / (2 * h);
        EXPECT_NEAR(dW[k], fd, tol_abs + tol_rel * std::fabs(fd)) << hidden_act << "/" << act << " w" << width << " param " << k;
        ++checked;
      }
      EXPECT_GT(checked, 20);
      for (int trial = 0; trial < 20; ++trial) {
        int idx = int(gen() % (m.enc_width * n));
        float keep = X0[idx];
        X0[idx] = keep + h;
        double fp = objective();
        X0[idx] = keep - h;
        double fm = objective();
        X0[idx] = keep;
        if (kinked(fp, objective(), fm)) continue;
        double fd = (fp - fm) / (2 * h);
        EXPECT_NEAR(dX0[idx], fd, tol_abs + tol_rel * std::fabs(fd)) << hidden_act << " input " << idx;
      }
    }
}

namespace {
float round_bf16(float x) { return kernels::from_bf16(kernels::to_bf16(x)); }

struct Bf16TrainResult {
  std::vector<float> out_pre, dW, dX0;
};

// The bf16 training semantics written out: weights, the input, activations and gradients rounded
// to bf16 where the kernels round them, every sum in double. Sample-major h[k][s * K + c].
Bf16TrainResult bf16_training_reference(const Network& net, const std::vector<float>& X0, const std::vector<float>& dout,
                                        int n) {
  const MlpLayout& m = net.mlp();
  const int W = int(m.width), H = int(m.n_hidden), K0 = int(m.first_cols), no = int(m.n_out);
  auto Wb = [&](int k, int r, int c) { return double(round_bf16(net.params()[m.offset[k] + size_t(r) * m.cols[k] + c])); };
  auto K = [&](int k) { return k == 0 ? K0 : W; };
  std::vector<std::vector<float>> h(H + 1);
  h[0].resize(size_t(n) * K0);
  for (int s = 0; s < n; ++s)
    for (int c = 0; c < K0; ++c) h[0][size_t(s) * K0 + c] = round_bf16(X0[size_t(c) * n + s]);
  for (int k = 0; k < H; ++k) {
    h[k + 1].resize(size_t(n) * W);
    for (int s = 0; s < n; ++s)
      for (int r = 0; r < W; ++r) {
        double a = 0;
        for (int c = 0; c < K(k); ++c) a += Wb(k, r, c) * h[k][size_t(s) * K(k) + c];
        h[k + 1][size_t(s) * W + r] = round_bf16(float(std::max(a, 0.0)));
      }
  }
  Bf16TrainResult R;
  R.out_pre.assign(size_t(no) * n, 0.0f);
  for (int s = 0; s < n; ++s)
    for (int o = 0; o < no; ++o) {
      double a = 0;
      for (int c = 0; c < W; ++c) a += Wb(H, o, c) * h[H][size_t(s) * W + c];
      R.out_pre[size_t(o) * n + s] = float(a);
    }
  R.dW.assign(m.n_params, 0.0f);
  R.dX0.assign(size_t(K0) * n, 0.0f);
  std::vector<double> db(size_t(n) * no);
  for (int s = 0; s < n; ++s)
    for (int o = 0; o < no; ++o) db[size_t(s) * no + o] = round_bf16(dout[size_t(o) * n + s]);
  for (int o = 0; o < no; ++o)
    for (int c = 0; c < W; ++c) {
      double a = 0;
      for (int s = 0; s < n; ++s) a += db[size_t(s) * no + o] * h[H][size_t(s) * W + c];
      R.dW[m.offset[H] + size_t(o) * m.cols[H] + c] = float(a);
    }
  std::vector<double> g(size_t(n) * W), gn(size_t(n) * W);
  for (int s = 0; s < n; ++s)
    for (int c = 0; c < W; ++c) {
      double a = 0;
      for (int o = 0; o < no; ++o) a += db[size_t(s) * no + o] * Wb(H, o, c);
      g[size_t(s) * W + c] = h[H][size_t(s) * W + c] > 0 ? round_bf16(float(a)) : 0.0;
    }
  for (int k = H - 1; k >= 0; --k) {
    for (int r = 0; r < W; ++r)
      for (int c = 0; c < K(k); ++c) {
        double a = 0;
        for (int s = 0; s < n; ++s) a += g[size_t(s) * W + r] * h[k][size_t(s) * K(k) + c];
        R.dW[m.offset[k] + size_t(r) * m.cols[k] + c] = float(a);
      }
    for (int s = 0; s < n; ++s)
      for (int c = 0; c < K(k); ++c) {
        double a = 0;
        for (int r = 0; r < W; ++r) a += g[size_t(s) * W + r] * Wb(k, r, c);
        if (k > 0) gn[size_t(s) * W + c] = h[k][size_t(s) * W + c] > 0 ? round_bf16(float(a)) : 0.0;
        else R.dX0[size_t(c) * n + s] = float(a);
      }
    std::swap(g, gn);
  }
  return R;
}

// max |a - b| over the first count values, relative to max |b|.
double relative_max_error(const float* a, const float* b, size_t count) {
  double err = 0, scale = 1e-30;
  for (size_t i = 0; i < count; ++i) {
    err = std::max(err, std::fabs(double(a[i]) - b[i]));
    scale = std::max(scale, std::fabs(double(b[i])));
  }
  return err / scale;
}
// |a - b| / |b| in the Euclidean norm.
double relative_l2_error(const float* a, const float* b, size_t count) {
  double err = 0, scale = 1e-60;
  for (size_t i = 0; i < count; ++i) {
    err += (double(a[i]) - b[i]) * (double(a[i]) - b[i]);
    scale += double(b[i]) * b[i];
  }
  return std::sqrt(err / scale);
}
}  // namespace

// The bf16 training forward and backward against the rounded reference (the kernels differ only by
// fp32 sums, which may move a value across a bf16 rounding boundary: well under 1 %), and against
// the fp32 path (bf16 rounding noise). Whether that noise costs quality is a training question:
// docs/benchmarks.md "bf16 training".
TEST(Mlp, Bf16TrainingMatchesRoundedReference) {
  struct Case {
    std::string name;
    Json config;
    uint32_t n_out;
  };
  const std::vector<Case> cases = {{"paper", preset_config("paper"), 1},
                                   {"small", preset_config("small"), 1},
                                   {"width 32", small_model("HashGrid", 32, 3), 1},
                                   {"width 128", small_model("HashGrid", 128, 1), 1},
                                   {"identity, sigmoid", small_model("Identity", 16, 2, "Sigmoid"), 1},
                                   {"3 outputs", small_model("HashGrid", 64, 2), 3}};
  for (const auto& [name, config, n_out] : cases) {
    SCOPED_TRACE(name);
    Network net(config, n_out);
    if (!net.bf16_training_supported()) GTEST_SKIP() << "no AVX512-BF16 on this CPU";
    net.init_params(3);
    const MlpLayout& m = net.mlp();
    const int n = 64;
    std::mt19937 gen(17);
    std::uniform_real_distribution<float> U(-1.f, 1.f);
    std::vector<float> X0(size_t(m.in_pad) * n, 0.0f), dout(size_t(m.n_out) * n);
    for (size_t i = 0; i < size_t(m.first_cols) * n; ++i) X0[i] = U(gen);
    for (float& d : dout) d = U(gen) / n;
    const Network::Bf16TrainWeights w = net.bf16_train_weights();
    std::vector<uint32_t> scratch(net.mlp_train_bf16_scratch(n));
    std::vector<float> pre(size_t(m.n_out) * n), out(pre.size()), dW(m.n_params, 0.0f), dX0(size_t(m.in_pad) * n, 0.0f);
    net.mlp_forward_train_bf16(X0.data(), n, w, scratch.data(), pre.data(), out.data());
    net.mlp_backward_train_bf16(dout.data(), n, w, scratch.data(), dW.data(), dX0.data());
    const Bf16TrainResult R = bf16_training_reference(net, X0, dout, n);
    EXPECT_LT(relative_max_error(pre.data(), R.out_pre.data(), pre.size()), 1e-2);
    for (size_t i = 0; i < pre.size(); ++i) EXPECT_EQ(out[i], activate(m.output_activation, pre[i]));
    for (uint32_t k = 0; k <= m.n_hidden; ++k) {
      const size_t count = m.rows[k] * m.cols[k];
      EXPECT_LT(relative_max_error(dW.data() + m.offset[k], R.dW.data() + m.offset[k], count), 1e-2) << "matrix " << k;
    }
    EXPECT_LT(relative_max_error(dX0.data(), R.dX0.data(), size_t(m.first_cols) * n), 1e-2);
    // The fp32 path computes the same quantities.
    std::vector<float> acts(net.acts_floats(n)), pre32(pre.size()), out32(pre.size()), dW32(m.n_params, 0.0f),
        dX032(dX0.size(), 0.0f), s32(2 * size_t(m.width) * n);
    net.mlp_forward(X0.data(), n, acts.data(), pre32.data(), out32.data());
    net.mlp_backward(X0.data(), acts.data(), dout.data(), n, dW32.data(), dX032.data(), s32.data());
    // bf16 rounding noise grows through the layers and more in the gradients (sums over 64 samples
    // of random-sign terms cancel, and a ReLU mask may flip), hence looser bounds there; a wiring
    // error would be ~100 %.
    EXPECT_LT(relative_l2_error(pre.data(), pre32.data(), pre.size()), 2e-2);
    EXPECT_LT(relative_l2_error(dW.data(), dW32.data(), m.n_params), 0.1);
    EXPECT_LT(relative_l2_error(dX0.data(), dX032.data(), size_t(m.first_cols) * n), 0.3);
  }
}

TEST(Mlp, ChunkForwardMatchesReferenceEvaluation) {
 for (const char* preset : {"paper", "small"}) {  // small: 8 encoding outputs zero-padded to 16
  Network net(preset_config(preset));
  net.init_params(1337);
  std::mt19937 gen(1);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  net.edit_params([&](float* p, size_t) {
    float* table = p + net.mlp().n_params;
    for (uint64_t k = 0; k < net.grid_params(); ++k) table[k] = (U(gen) - 0.5f) * 0.2f;
  });
  std::vector<float> coords(3 * 300), out(300);
  for (auto& c : coords) c = U(gen);
  net.infer(coords.data(), 300, out.data());
  for (int i = 0; i < 300; i += 7) {
    float ref = net.eval_reference(coords[3 * i], coords[3 * i + 1], coords[3 * i + 2]);
    EXPECT_NEAR(out[i], ref, 1e-5 + 1e-4 * std::fabs(ref)) << preset << " " << i;
  }
 }
}

TEST(Loss, ValuesAndGradientsMatchDefinitionAndFiniteDifferences) {
  const LossType types[] = {LossType::L1, LossType::L2, LossType::RelativeL2, LossType::RelativeL1};
  const float inv_n = 0.25f;
  for (LossType t : types)
    for (float pred : {-0.7f, 0.2f, 1.3f}) {
      float target = 0.4f, g, gp, gm;
      float v = loss_value_and_grad(t, pred, target, inv_n, &g);
      float d = pred - target;
      float expect = t == LossType::L1   ? std::fabs(d) * inv_n
                     : t == LossType::L2 ? d * d * inv_n
                     : t == LossType::RelativeL2 ? d * d / (pred * pred + 0.01f) * inv_n
                                                 : std::fabs(d) / (std::fabs(pred) + 0.01f) * inv_n;
      EXPECT_FLOAT_EQ(v, expect);
      if (t == LossType::L1 || t == LossType::L2) {  // the relative losses hold the denominator constant
        const float h = 1e-3f;
        float fd = (loss_value_and_grad(t, pred + h, target, inv_n, &gp) -
                    loss_value_and_grad(t, pred - h, target, inv_n, &gm)) / (2 * h);
        EXPECT_NEAR(g, fd, 1e-3) << loss_name(t);
      } else {
        float den = t == LossType::RelativeL2 ? pred * pred + 0.01f : std::fabs(pred) + 0.01f;
        float fd_num = t == LossType::RelativeL2 ? 2 * d : std::copysign(1.0f, d);
        EXPECT_FLOAT_EQ(g, fd_num / den * inv_n);
      }
    }
  float g;
  loss_value_and_grad(LossType::L1, 0.5f, 0.5f, 1.0f, &g);  // diff = +0 gives +1 (tcnn)
  EXPECT_EQ(g, 1.0f);
}

TEST(Adam, MatchesHandComputedUpdatesAndLazyGridSemantics) {
  AdamConfig a;
  a.learning_rate = 0.01f;
  a.beta1 = 0.9f;
  a.beta2 = 0.999f;
  a.epsilon = 1e-8f;
  a.l2_reg = 0.1f;
  DecayConfig d;
  // params: [0] matrix, [1] grid touched, [2] grid untouched
  Adam opt(a, d, 3, 1);
  float w[3] = {1.0f, 2.0f, 3.0f};
  float g[3] = {0.5f, -0.25f, 0.0f};
  opt.step(w, g);
  // Matrix param: g' = 0.5 + 0.1 * 1 = 0.6; m = 0.06; v = 0.00036; lr_t = 0.01*sqrt(0.001)/0.1
  double m0 = 0.1 * 0.6, v0 = 0.001 * 0.36, lrt = 0.01 * std::sqrt(1 - 0.999) / (1 - 0.9);
  EXPECT_NEAR(w[0], 1.0 - lrt / (std::sqrt(v0) + 1e-8) * m0, 1e-6);
  double m1 = 0.1 * -0.25, v1 = 0.001 * 0.0625;  // grid param: no l2
  EXPECT_NEAR(w[1], 2.0 - lrt / (std::sqrt(v1) + 1e-8) * m1, 1e-6);
  EXPECT_EQ(w[2], 3.0f);  // zero gradient: skipped entirely
  EXPECT_EQ(opt.c[2], 0u);
  EXPECT_EQ(g[0], 0.0f);  // gradients are consumed
  // Second step touching only param 2: its own step count starts at 1 (bias correction per param).
  float g2[3] = {0.0f, 0.0f, 1.0f};
  float w1_before = w[1];
  opt.step(w, g2);
  EXPECT_EQ(w[1], w1_before);
  EXPECT_EQ(opt.c[1], 1u);
  EXPECT_EQ(opt.c[2], 1u);
  EXPECT_NEAR(w[2], 3.0 - lrt / (std::sqrt(0.001) + 1e-8) * 0.1, 1e-6);
  EXPECT_EQ(opt.c[0], 2u);  // matrix params always step (l2 keeps them moving)
}

TEST(Adam, ExponentialDecayScheduleOfThePaper) {
  Network net(preset_config("paper"));
  const AdamConfig& a = net.config().adam;
  const DecayConfig& d = net.config().decay;
  EXPECT_FLOAT_EQ(Adam::learning_rate_at(a, d, 0), 0.005f);
  EXPECT_FLOAT_EQ(Adam::learning_rate_at(a, d, 1999), 0.005f);
  EXPECT_FLOAT_EQ(Adam::learning_rate_at(a, d, 2000), 0.005f * 0.99f);
  EXPECT_FLOAT_EQ(Adam::learning_rate_at(a, d, 2999), 0.005f * 0.99f);
  EXPECT_FLOAT_EQ(Adam::learning_rate_at(a, d, 3000), 0.005f * 0.99f * 0.99f);
  EXPECT_NEAR(Adam::learning_rate_at(a, d, 19999), 0.005 * std::pow(0.99, 18), 1e-8);
  // The stateful schedule inside step() agrees with the closed form.
  DecayConfig dd = d;
  dd.decay_start = 3;
  dd.decay_interval = 2;
  Adam opt(a, dd, 1, 1);
  float w = 0, g = 0;
  for (uint64_t t = 0; t < 12; ++t) {
    opt.step(&w, &g);
    EXPECT_FLOAT_EQ(opt.current_learning_rate(), Adam::learning_rate_at(a, dd, t)) << t;
  }
}

namespace {
// A smooth analytic volume in memory.
std::vector<float> smooth_volume(int n) {
  std::vector<float> v(size_t(n) * n * n);
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        float u = (x + 0.5f) / n, w = (y + 0.5f) / n, t = (z + 0.5f) / n;
        v[(size_t(z) * n + y) * n + x] =
            0.5f + 0.25f * std::sin(6.f * u) * std::cos(5.f * w) + 0.2f * std::exp(-20.f * ((t - 0.5f) * (t - 0.5f)));
      }
  return v;
}
}  // namespace

TEST(CpuTrainer, LearnsASmoothVolumeAndIsDeterministic) {
  const int n = 24;
  std::vector<float> vol = smooth_volume(n);
  GridView g{vol.data(), n, n, n};
  auto run = [&](int steps) {
    auto net = std::make_unique<Network>(preset_config("small"));
    net->init_params(42);
    CpuTrainer tr(*net, std::make_shared<InCoreSampler>(g), TrainOptions{8192, 42});
    for (int i = 0; i < steps; ++i) tr.step();
    return std::make_pair(std::move(net), tr.loss_history());
  };
  auto [a, la] = run(150);
  auto [b, lb] = run(150);
  EXPECT_EQ(a->params(), b->params());  // same seed, same thread count: bit-identical
  EXPECT_EQ(la, lb);
  EXPECT_LT(la.back(), la.front() * 0.2f);
  // Adam keeps the fp16 working copy equal to fp16(master) for every grid parameter.
  for (uint64_t k = 0; k < a->grid_params(); ++k) ASSERT_EQ(a->grid_half()[k], float_to_half(a->grid_table()[k])) << k;
  // Decoded at voxel centres, the model is close to the volume.
  std::vector<float> out(vol.size());
  a->infer_fn(
      int64_t(vol.size()),
      [&](int64_t i, float* x, float* y, float* z) {
        *x = (i % n + 0.5f) / n;
        *y = ((i / n) % n + 0.5f) / n;
        *z = (i / (n * n) + 0.5f) / n;
      },
      out.data());
  double mse = 0;
  for (size_t i = 0; i < vol.size(); ++i) mse += double(out[i] - vol[i]) * (out[i] - vol[i]);
  mse /= vol.size();
  double psnr = 10 * std::log10(1.0 / mse);
  EXPECT_GT(psnr, 30.0);
}

// A small grid's gradient scattered per chunk into per-thread copies (the default for the small
// config) is the gradient of the separate level-by-level pass: on one thread the same sums in the same
// order (bit-identical models), on two the same up to the order of the two threads' partial sums.
TEST(CpuTrainer, PrivateGridGradientsEqualTheSeparatePass) {
  const int n = 24;
  const std::vector<float> vol = smooth_volume(n);
  const GridView g{vol.data(), n, n, n};
  auto run = [&](uint64_t private_max_bytes, int steps) {
    auto net = std::make_unique<Network>(preset_config("small"));
    net->init_params(7);
    TrainOptions o{8192, 7};
    o.private_grid_grad_max_bytes = private_max_bytes;
    CpuTrainer tr(*net, std::make_shared<InCoreSampler>(g), o);
    for (int i = 0; i < steps; ++i) tr.step();
    return std::make_pair(std::move(net), tr.loss_history());
  };
  const int threads = num_threads();
  set_num_threads(1);
  auto [p1, lp1] = run(TrainOptions{}.private_grid_grad_max_bytes, 5);
  auto [s1, ls1] = run(0, 5);
  EXPECT_EQ(p1->params(), s1->params());
  EXPECT_EQ(lp1, ls1);
  set_num_threads(2);
  auto [p2, lp2] = run(TrainOptions{}.private_grid_grad_max_bytes, 40);
  auto [s2, ls2] = run(0, 40);
  set_num_threads(threads);
  EXPECT_EQ(lp2[0], ls2[0]);  // the first loss precedes any update
  for (size_t i = 1; i < lp2.size(); ++i) EXPECT_NEAR(lp2[i], ls2[i], 1e-3 * ls2[i]) << i;
  EXPECT_LT(lp2.back(), lp2.front() * 0.5f);
}

// The step's shared tail chunks go to whichever thread is free, yet the trained model depends only on
// the thread count: a sampler that slows one thread or the other changes who runs which chunk (counted
// here), not one bit of the parameters, with a private grid gradient (small config) and with the
// level pass. Against dealing every chunk round-robin the sums differ only in order.
TEST(CpuTrainer, SharedTailChunksGiveTheSameModelWhicheverThreadRunsThem) {
  const int n = 24;
  const std::vector<float> vol = smooth_volume(n);
  const GridView g{vol.data(), n, n, n};
  struct SlowThread : Sampler {
    InCoreSampler inner;
    int slow;
    mutable std::atomic<int> chunks[2] = {0, 0};
    SlowThread(GridView g, int slow) : inner(g), slow(slow) {}
    void sample(uint64_t seed, uint64_t step, uint64_t chunk, int n, float* x, float* y, float* z,
                float* target) const override {
      const int t = omp_get_thread_num();
      ++chunks[t & 1];
      if (t == slow) std::this_thread::sleep_for(std::chrono::microseconds(300));
      inner.sample(seed, step, chunk, n, x, y, z, target);
    }
  };
  auto run = [&](int slow, int64_t tail, uint64_t private_max_bytes, int* chunks0) {
    auto net = std::make_unique<Network>(preset_config("small"));
    net->init_params(7);
    TrainOptions o{8192, 7};  // 32 chunks: 16 dealt, 16 shared
    o.shared_tail_chunks = tail;
    o.private_grid_grad_max_bytes = private_max_bytes;
    auto sampler = std::make_shared<SlowThread>(g, slow);
    CpuTrainer tr(*net, sampler, o);
    for (int i = 0; i < 6; ++i) tr.step();
    if (chunks0) *chunks0 = sampler->chunks[0];
    return std::make_pair(std::move(net), tr.loss_history());
  };
  const int threads = num_threads();
  set_num_threads(2);
  int team = 0;
  parallel_threads([&](int t, int nt) {
    if (t == 0) team = nt;
  });
  if (team < 2) {  // e.g. OMP_THREAD_LIMIT=1: nothing is shared on one thread
    set_num_threads(threads);
    GTEST_SKIP() << "needs two OpenMP threads";
  }
  for (const uint64_t private_max : {TrainOptions{}.private_grid_grad_max_bytes, uint64_t(0)}) {
    int c0_slow = 0, c0_fast = 0;
    auto [a, la] = run(0, 32, private_max, &c0_slow);
    auto [b, lb] = run(1, 32, private_max, &c0_fast);
    EXPECT_LT(c0_slow, c0_fast) << "the slowed thread should have claimed fewer shared chunks";
    EXPECT_EQ(a->params(), b->params()) << "private grid " << private_max;
    EXPECT_EQ(la, lb);
    auto [r, lr] = run(-1, 0, private_max, nullptr);
    EXPECT_EQ(la[0], lr[0]);  // the first loss precedes any update
    for (size_t i = 1; i < la.size(); ++i) EXPECT_NEAR(la[i], lr[i], 1e-3 * lr[i]) << i;
  }
  set_num_threads(threads);
}

// The in-core sampler's targets are grid_lookup's bits.
TEST(Sampler, InCoreTargetsAreTheGridLookups) {
  std::vector<float> vol = smooth_volume(24);
  for (const GridView g : {GridView{vol.data(), 24, 24, 24}, GridView{vol.data(), 1, 24, 24}}) {
    const InCoreSampler sampler(g);
    const int n = 1000;
    std::vector<float> x(n), y(n), z(n), target(n);
    sampler.sample(3, 7, 11, n, x.data(), y.data(), z.data(), target.data());
    for (int i = 0; i < n; ++i) ASSERT_EQ(target[i], grid_lookup(g, x[i], y[i], z[i])) << i << " nx " << g.nx;
  }
}

TEST(CpuTrainer, RejectsBadBatch) {
  Network net(preset_config("small"));
  std::vector<float> vol(8, 0.f);
  GridView g{vol.data(), 2, 2, 2};
  EXPECT_THROW(CpuTrainer(net, std::make_shared<InCoreSampler>(g), TrainOptions{1000, 1}), std::exception);
}

TEST(TargetRatio, SizesTheModelNearTheRequestedRatio) {
  const uint64_t volume_bytes = 16u << 20;  // bonsai: 256^3 uint8
  for (double ratio : {4.0, 16.0, 50.0, 200.0}) {
    std::string note;
    const uint64_t budget = uint64_t(double(volume_bytes) / ratio);
    ModelConfig c = size_config_for_bytes(ModelConfig::from_json(preset_config("paper")), budget, 4.0, &note);
    // The table moves in factors of two: the parameters at 4 bits each land within 2x of the budget.
    const double bytes = double(count_params(c)) * 4 / 8;
    EXPECT_GT(bytes, double(budget) / 2) << note;
    EXPECT_LT(bytes, double(budget) * 2) << note;
    EXPECT_NE(note.find("levels"), std::string::npos);
    // The MLP and everything but the grid size is kept.
    EXPECT_EQ(c.to_json()["network"], Network(preset_config("paper")).config_json()["network"]);
  }
  EXPECT_THROW(size_config_for_bytes(load_config("paper"), 1000, -1, nullptr), std::exception);
}
