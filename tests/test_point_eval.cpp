// PointEvaluator (single-point network evaluation for in-shader rendering) against Network::infer
// and Network::eval_reference: every encoding type, grid type and interpolation, widths 16..128
// plus non-multiple-of-16 CutlassMLP widths, hidden ReLU / None, output activations, initialised
// and randomised (large) weights, boundary points, every compiled SIMD target.
#include <gtest/gtest.h>
#include <hwy/targets.h>
#include <cmath>
#include <cstring>
#include <random>
#include <vector>
#include "vnr/core/parallel.h"
#include "vnr/nn/network.h"
#include "vnr/nn/mlp_bf16.h"
#include "vnr/nn/point_eval.h"
#include "test_support.h"

using namespace vnr;
using namespace vnr::test;

namespace {

Json hashgrid(int L, int F, int log2T, int base, double scale = 2.0, std::string interp = "Linear",
              std::string otype = "HashGrid") {
  return Json{{"otype", otype},       {"n_levels", L},         {"n_features_per_level", F},
              {"log2_hashmap_size", log2T}, {"base_resolution", base}, {"per_level_scale", scale},
              {"interpolation", interp}};
}

struct Case {
  std::string name;
  Json config;
};

std::vector<Case> cases() {
  return {
      {"paper", preset_config("paper")},
      {"small", preset_config("small")},
      {"tiny", preset_config("tiny")},
      {"hash_L16F2_w64x4", mlp_model_config(hashgrid(16, 2, 19, 16, 1.5), 64, 4)},
      {"hash_L8F4_w32x3", mlp_model_config(hashgrid(8, 4, 15, 8, 1.6), 32, 3)},
      {"hash_L12F1_w16x2", mlp_model_config(hashgrid(12, 1, 14, 4, 1.7), 16, 2)},
      {"dense_L4F4_w32x2", mlp_model_config(hashgrid(4, 4, 19, 3, 1.5, "Linear", "DenseGrid"), 32, 2)},
      {"dense_L3F2_w16x3", mlp_model_config(hashgrid(3, 2, 19, 5, 2.0, "Linear", "DenseGrid"), 16, 3)},
      {"tiled_L4F2_w16x2", mlp_model_config(hashgrid(4, 2, 19, 3, 1.7, "Linear", "TiledGrid"), 16, 2)},
      {"tiled_L4F8_w64x2", mlp_model_config(hashgrid(4, 8, 19, 4, 2.0, "Linear", "TiledGrid"), 64, 2)},
      {"smoothstep_w32x2", mlp_model_config(hashgrid(6, 2, 14, 4, 2.0, "Smoothstep"), 32, 2)},
      {"smoothstep_F8_w64x2", mlp_model_config(hashgrid(4, 8, 16, 4, 2.0, "Smoothstep"), 64, 2)},
      {"nearest_w16x2", mlp_model_config(hashgrid(5, 2, 14, 4, 2.0, "Nearest"), 16, 2)},
      {"hash_w128x3", mlp_model_config(hashgrid(16, 2, 17, 16, 1.5), 128, 3)},
      {"cutlass_w24x2", mlp_model_config(hashgrid(4, 2, 14, 4), 24, 2)},
      {"cutlass_w100x2_sigmoid", mlp_model_config(hashgrid(4, 4, 14, 4), 100, 2, "ReLU", "Sigmoid")},
      {"hidden_none_w32x3", mlp_model_config(hashgrid(4, 2, 14, 4), 32, 3, "None")},
      {"hidden_none_w24x2", mlp_model_config(hashgrid(4, 2, 14, 4), 24, 2, "None", "Softplus")},
      {"exp_output_w16x1", mlp_model_config(hashgrid(4, 2, 14, 4), 16, 1, "ReLU", "Exponential")},
      {"frequency_w64x2", mlp_model_config(Json{{"otype", "Frequency"}, {"n_frequencies", 6}}, 64, 2)},
      {"frequency_w32x2_sigmoid", mlp_model_config(Json{{"otype", "Frequency"}, {"n_frequencies", 4}}, 32, 2, "ReLU", "Sigmoid")},
      {"oneblob_w32x2", mlp_model_config(Json{{"otype", "OneBlob"}, {"n_bins", 8}}, 32, 2)},
      {"identity_w16x2", mlp_model_config(Json{{"otype", "Identity"}, {"scale", 2.0}, {"offset", -0.5}}, 16, 2)},
  };
}

// Grid parameters U[-1, 1] (fp16 working copy re-synced) and MLP matrices scaled up, so that outputs
// are of order 0.1-10 rather than ~1e-5 (tcnn's grid init is U[-1e-4, 1e-4]).
void randomise(Network& net, uint32_t seed, float mlp_scale = 1.5f) {
  std::mt19937 gen(seed);
  std::uniform_real_distribution<float> U(-1.f, 1.f);
  net.edit_params([&](float* p, size_t) {
    for (uint64_t i = 0; i < net.mlp().n_params; ++i) p[i] *= mlp_scale;
  });
  if (net.has_grid()) {
    net.edit_params([&](float* p, size_t) {
      float* table = p + net.mlp().n_params;
      for (uint64_t i = 0; i < net.grid_params(); ++i) table[i] = U(gen);
    });
  }
}

std::vector<float> random_points(int n, uint32_t seed) {
  std::mt19937 gen(seed);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  std::vector<float> p(3 * size_t(n));
  for (auto& v : p) v = U(gen);
  return p;
}

// Corners of the cube and points on exactly representable lattice positions, plus values near 1.
std::vector<float> boundary_points() {
  const float vals[] = {0.0f, 0.999999f, 0.5f, 0.25f, 0.75f, 0.125f, 1.0f / 3.0f, 0.9999999f, 1e-7f, 1.0f};
  std::vector<float> p;
  for (float a : vals)
    for (float b : {0.0f, 0.999999f, 0.5f, 1.0f})
      for (float c : {0.0f, 0.999999f, 0.0625f}) p.insert(p.end(), {a, b, c});
  return p;
}

// |got - want| <= 1e-5 * (tol_abs + |want|); tol_abs = 1 is the plain bound, smaller values tighten it
// for networks whose outputs are small.
void expect_close(const std::vector<float>& got, const std::vector<float>& want, const std::vector<float>& pts,
                  const char* what, double tol_abs = 1.0) {
  ASSERT_EQ(got.size(), want.size());
  int bad = 0;
  double worst = 0;
  for (size_t i = 0; i < got.size(); ++i) {
    const double tol = 1e-5 * (tol_abs + std::fabs(double(want[i])));
    const double diff = std::fabs(double(got[i]) - double(want[i]));
    worst = std::max(worst, diff / tol);
    if (!(diff <= tol) && bad++ < 5)
      ADD_FAILURE() << what << ": point " << i << " (" << pts[3 * i] << ", " << pts[3 * i + 1] << ", "
                    << pts[3 * i + 2] << "): got " << got[i] << " want " << want[i];
  }
  EXPECT_EQ(bad, 0) << what << ": worst diff / tol = " << worst;
}

double mean_abs(const std::vector<float>& v) {
  double s = 0;
  for (float x : v) s += std::fabs(x);
  return s / double(v.size());
}

// Checks one network on random + boundary points: eval vs infer, eval vs eval_reference,
// encode vs encode_point (bit-identical), mlp(encode) == eval.
// Tolerance: 1e-5 * (1 + |value|), or with `relative` 1e-5 * (mean |output| + |value|), which is
// tighter for the tiny outputs of freshly initialised networks and scales with the large ones.
void check_network(const Network& net, const char* label, bool relative = false, int n_random = 2000) {
  SCOPED_TRACE(label);
  std::vector<float> pts = random_points(n_random, 17);
  std::vector<float> bnd = boundary_points();
  pts.insert(pts.end(), bnd.begin(), bnd.end());
  const int64_t n = int64_t(pts.size() / 3);
  std::vector<float> want(n), got(n), ref(n);
  net.infer(pts.data(), n, want.data());
  const double mag = mean_abs(want);
  const double tol_abs = relative ? mag : 1.0;
  if (!relative) EXPECT_GT(mag, 1e-2) << "outputs too small for a meaningful comparison";
  EXPECT_GT(mag, 1e-7) << "outputs vanish";
  for (bool skip : {true, false}) {
    PointEvaluator pe(net, skip);
    EXPECT_EQ(pe.skips_zeros(), skip && net.mlp().activation == Activation::ReLU && net.mlp().width > 32);
    for (int64_t i = 0; i < n; ++i) got[i] = pe.eval(pts[3 * i], pts[3 * i + 1], pts[3 * i + 2]);
    expect_close(got, want, pts, skip ? "eval vs infer (skip zeros)" : "eval vs infer (dense)", tol_abs);
  }
  PointEvaluator pe(net);
  const uint32_t in_pad = net.mlp().in_pad, ew = net.mlp().enc_width;
  std::vector<float> enc(in_pad), enc_ref(ew);
  int enc_mismatch = 0;
  for (int64_t i = 0; i < n; ++i) {
    const float* p = &pts[3 * i];
    ref[i] = net.eval_reference(p[0], p[1], p[2]);
    pe.encode(p[0], p[1], p[2], enc.data());
    net.encode_point(p, enc_ref.data());
    enc_mismatch += std::memcmp(enc.data(), enc_ref.data(), sizeof(float) * ew) != 0;
    for (uint32_t j = ew; j < in_pad; ++j) enc_mismatch += enc[j] != net.mlp().pad_value;
    const float e = pe.eval(p[0], p[1], p[2]);
    const float mm = pe.mlp(enc.data());
    if (std::memcmp(&e, &mm, 4) != 0) ADD_FAILURE() << "mlp(encode(p)) != eval(p) at " << i << ": " << mm << " vs " << e;
    got[i] = e;
  }
  EXPECT_EQ(enc_mismatch, 0) << "encode() differs from Network::encode_point";
  expect_close(got, ref, pts, "eval vs eval_reference", tol_abs);
}

}  // namespace

TEST(PointEval, MatchesInferInitialisedWeights) {
  for (const Case& c : cases()) {
    Network net(c.config);
    net.init_params(11);
    check_network(net, c.name.c_str(), true);
  }
}

TEST(PointEval, MatchesInferRandomisedWeights) {
  for (const Case& c : cases()) {
    Network net(c.config);
    net.init_params(12);
    randomise(net, 99);
    check_network(net, c.name.c_str());
  }
}

// Outputs of order 10-1000 (relative tolerance), and a ReLU network whose activations are mostly zero.
TEST(PointEval, LargeAndSparseActivations) {
  for (const char* name : {"paper", "small"}) {
    Network net(preset_config(name));
    net.init_params(3);
    randomise(net, 5, 3.0f);
    check_network(net, (std::string(name) + "_large").c_str(), true, 1000);
  }
  Network net(mlp_model_config(hashgrid(8, 4, 16, 4), 64, 4));
  net.init_params(4);
  randomise(net, 6);
  // Negative bias-like shift: most hidden pre-activations negative, so compaction removes most inputs.
  net.edit_params([&](float* p, size_t) {
    for (uint64_t i = net.mlp().offset[1]; i < net.mlp().offset[net.mlp().n_hidden]; ++i) p[i] -= 0.08f;
  });
  {  // confirm the hidden activations feeding layers 2.. are mostly exact zeros
    const MlpLayout& m = net.mlp();
    const int n = 256;
    std::vector<float> pts = random_points(n, 9), x(n), y(n), z(n), X0(size_t(m.in_pad) * n),
                       acts(net.acts_floats(n)), pre(n), out(n);
    for (int i = 0; i < n; ++i) x[i] = pts[3 * i], y[i] = pts[3 * i + 1], z[i] = pts[3 * i + 2];
    net.encode(x.data(), y.data(), z.data(), n, X0.data());
    net.mlp_forward(X0.data(), n, acts.data(), pre.data(), out.data());
    size_t zeros = 0, total = size_t(m.n_hidden - 1) * m.width * n;
    for (size_t i = size_t(m.width) * n; i < acts.size(); ++i) zeros += acts[i] == 0.0f;
    EXPECT_GT(double(zeros) / double(total), 0.6);
  }
  check_network(net, "sparse", true, 1000);
}

// Points outside [0, 1] take the scalar encoding path; it must still match infer.
TEST(PointEval, OutsideUnitCube) {
  Network net(preset_config("paper"));
  net.init_params(7);
  randomise(net, 8);
  std::vector<float> pts;
  for (float a : {-0.25f, -1e-6f, 1.0f + 1e-6f, 1.3f, 0.5f})
    for (float b : {0.3f, -0.01f, 1.01f})
      for (float c : {0.7f, 2.0f}) pts.insert(pts.end(), {a, b, c});
  const int64_t n = int64_t(pts.size() / 3);
  std::vector<float> want(n), got(n);
  net.infer(pts.data(), n, want.data());
  PointEvaluator pe(net);
  for (int64_t i = 0; i < n; ++i) got[i] = pe.eval(pts[3 * i], pts[3 * i + 1], pts[3 * i + 2]);
  expect_close(got, want, pts, "outside");
}

// Every compiled-and-supported SIMD target: bit-identical encodings, eval within tolerance.
TEST(PointEval, EverySimdTarget) {
  for (const char* cname : {"paper", "small"}) {
    Network net(preset_config(cname));
    net.init_params(21);
    randomise(net, 22);
    std::vector<float> pts = random_points(500, 23);
    std::vector<float> bnd = boundary_points();
    pts.insert(pts.end(), bnd.begin(), bnd.end());
    const int64_t n = int64_t(pts.size() / 3);
    std::vector<float> want(n), got(n);
    net.infer(pts.data(), n, want.data());
    std::vector<float> enc(net.mlp().in_pad), enc_ref(net.mlp().enc_width);
    for (int64_t t : hwy::SupportedAndGeneratedTargets()) {
      hwy::SetSupportedTargetsForTest(t);
      SCOPED_TRACE(std::string(cname) + " " + hwy::TargetName(t));
      PointEvaluator pe(net);
      EXPECT_STREQ(pe.simd_target(), hwy::TargetName(t));
      for (int64_t i = 0; i < n; ++i) {
        const float* p = &pts[3 * i];
        got[i] = pe.eval(p[0], p[1], p[2]);
        pe.encode(p[0], p[1], p[2], enc.data());
        net.encode_point(p, enc_ref.data());
        ASSERT_EQ(std::memcmp(enc.data(), enc_ref.data(), sizeof(float) * enc_ref.size()), 0) << "point " << i;
      }
      expect_close(got, want, pts, "eval vs infer");
    }
    hwy::SetSupportedTargetsForTest(0);
  }
}

// eval() is const and thread-safe: concurrent evaluation gives the serial results bit for bit.
TEST(PointEval, ThreadSafe) {
  Network net(preset_config("paper"));
  net.init_params(31);
  randomise(net, 32);
  const PointEvaluator pe(net);
  const int n = 4000;
  std::vector<float> pts = random_points(n, 33), serial(n), par(n);
  for (int i = 0; i < n; ++i) serial[i] = pe.eval(pts[3 * i], pts[3 * i + 1], pts[3 * i + 2]);
  parallel_for(n, [&](int64_t i) { par[i] = pe.eval(pts[3 * i], pts[3 * i + 1], pts[3 * i + 2]); });
  EXPECT_EQ(std::memcmp(serial.data(), par.data(), sizeof(float) * n), 0);
}

// Movable: the moved-to evaluator keeps working (weights are heap-owned).
TEST(PointEval, Movable) {
  Network net(preset_config("small"));
  net.init_params(41);
  randomise(net, 42);
  PointEvaluator a(net);
  const float before = a.eval(0.3f, 0.6f, 0.9f);
  PointEvaluator b(std::move(a));
  EXPECT_EQ(b.eval(0.3f, 0.6f, 0.9f), before);
  std::vector<PointEvaluator> v;
  v.push_back(std::move(b));
  EXPECT_EQ(v[0].eval(0.3f, 0.6f, 0.9f), before);
}

// Non-finite weights disable the zero-skipping (0 * inf must stay NaN as in infer).
TEST(PointEval, NonFiniteWeightsDisableSkipping) {
  Network net(preset_config("small"));
  net.init_params(51);
  net.edit_params([&](float* p, size_t) { p[net.mlp().offset[1] + 3] = INFINITY; });
  PointEvaluator pe(net);
  EXPECT_FALSE(pe.skips_zeros());
  std::vector<float> pts = random_points(200, 52), want(200), got(200);
  net.infer(pts.data(), 200, want.data());
  for (int i = 0; i < 200; ++i) {
    got[i] = pe.eval(pts[3 * i], pts[3 * i + 1], pts[3 * i + 2]);
    if (std::isnan(want[i])) EXPECT_TRUE(std::isnan(got[i])) << i;
    else if (std::isinf(want[i])) EXPECT_EQ(got[i], want[i]) << i;
    else EXPECT_NEAR(got[i], want[i], 1e-5 * (1 + std::fabs(want[i]))) << i;
  }
}

// prefetch() is only a hint: any point (outside the cube, NaN, parameter-free encodings) is fine and
// results do not change.
TEST(PointEval, PrefetchHintHasNoEffect) {
  for (const char* cname : {"paper", "small"}) {
    Network net(preset_config(cname));
    net.init_params(61);
    randomise(net, 62);
    PointEvaluator pe(net);
    std::vector<float> pts = random_points(500, 63);
    for (int i = 0; i < 500; ++i) {
      const float* p = &pts[3 * i];
      const float before = pe.eval(p[0], p[1], p[2]);
      pe.prefetch(p[0], p[1], p[2]);
      pe.prefetch(-3.0f, 2.5f, NAN);
      pe.prefetch(1.0f, 1.0f, 1.0f);
      const float after = pe.eval(p[0], p[1], p[2]);
      ASSERT_EQ(std::memcmp(&before, &after, 4), 0);
    }
  }
  Network net(mlp_model_config(Json{{"otype", "Frequency"}, {"n_frequencies", 4}}, 32, 2));
  net.init_params(64);
  PointEvaluator pe(net);
  pe.prefetch(0.5f, 0.5f, 0.5f);
  EXPECT_NEAR(pe.eval(0.5f, 0.5f, 0.5f), net.eval_reference(0.5f, 0.5f, 0.5f), 1e-5);
}

// bf16 inference (Precision::BF16, AVX512-BF16 CPUs): the point evaluator and the batched path use
// the same bf16 operands and differ only in fp32 summation order, which can move a hidden value
// across a bf16 rounding boundary (one bf16 ulp, 2^-8 relative); both stay close to fp32.
TEST(PointEval, Bf16MatchesBatchedBf16AndStaysNearFp32) {
  if (!kernels::bf16_supported()) GTEST_SKIP() << "this CPU has no AVX512-BF16";
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.name);
    Network net(c.config);
    net.init_params(12);
    randomise(net, 99);
    std::vector<float> pts = random_points(2000, 17);
    const int64_t n = int64_t(pts.size() / 3);
    std::vector<float> fp32(n), bf16(n), point(n);
    net.infer(pts.data(), n, fp32.data());
    net.set_inference_precision(Precision::BF16);
    const bool applies = net.mlp().activation == Activation::ReLU && net.mlp().width % 2 == 0;
    ASSERT_EQ(net.inference_precision(), applies ? Precision::BF16 : Precision::FP32);
    net.infer(pts.data(), n, bf16.data());
    const double mag = mean_abs(fp32);
    double worst_pt = 0, worst_fp = 0;
    for (bool skip : {true, false}) {
      PointEvaluator pe(net, skip);
      ASSERT_EQ(pe.precision(), net.mlp().width > 16 ? net.inference_precision() : Precision::FP32);
      std::vector<float> enc(pe.in_pad());
      for (int64_t i = 0; i < n; ++i) {
        const float* p = &pts[3 * i];
        point[i] = pe.eval(p[0], p[1], p[2]);
        pe.encode(p[0], p[1], p[2], enc.data());
        const float mm = pe.mlp(enc.data());
        ASSERT_EQ(std::memcmp(&mm, &point[i], 4), 0) << "mlp(encode(p)) != eval(p) at " << i;
      }
      // a 16-wide network's point evaluator stays fp32: compare it with the fp32 batched values
      const std::vector<float>& same = pe.precision() == Precision::BF16 ? bf16 : fp32;
      for (int64_t i = 0; i < n; ++i)
        worst_pt = std::max(worst_pt, std::fabs(double(point[i]) - same[i]) / (mag + std::fabs(same[i])));
    }
    for (int64_t i = 0; i < n; ++i)
      worst_fp = std::max(worst_fp, std::fabs(double(bf16[i]) - fp32[i]) / (mag + std::fabs(fp32[i])));
    if (!applies) {
      EXPECT_EQ(bf16, fp32);
      continue;
    }
    // Bounds several times the rounding noise of these cases (randomised weights, outputs ~1-10);
    // against the rounded reference only the fp32 summation order differs.
    EXPECT_LT(worst_pt, 5e-3);
    EXPECT_LT(worst_fp, 6e-2);
    EXPECT_GT(worst_fp, 0.0);  // bf16 really ran
  }
}
