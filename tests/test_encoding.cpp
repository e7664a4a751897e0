// Grid-encoding semantics against the bit-exact vectors of tests/data/grid_vectors.json
// (docs/semantics.md A.10), parameter counts against the paper's appendix,
// and finite-difference checks of every encoding's gradients.
#include <gtest/gtest.h>
#include <hwy/targets.h>
#include <cmath>
#include <cstring>
#include <random>
#include "vnr/fileio.h"
#include "vnr/json.h"
#include "vnr/core/rng.h"
#include "vnr/nn/network.h"
#include "test_support.h"

using namespace vnr;
using vnr::test::bits;

namespace {

Json vectors() { return parse_json_file(std::string(VNR_TEST_DATA_DIR) + "/grid_vectors.json"); }

Json model(Json enc, std::string net = "FullyFusedMLP", int width = 16, int hidden = 1) {
  return Json{{"encoding", enc},
              {"network", {{"otype", net}, {"n_neurons", width}, {"n_hidden_layers", hidden}}},
              {"loss", {{"otype", "L1"}}}};
}

Json hashgrid(int L, int F, int log2T, int base, std::string interp = "Linear", std::string otype = "HashGrid") {
  return Json{{"otype", otype},          {"n_levels", L},          {"n_features_per_level", F},
              {"log2_hashmap_size", log2T}, {"base_resolution", base}, {"interpolation", interp}};
}

}  // namespace

TEST(GridEncoding, LevelTableMatchesVectors) {
  Json v = vectors();
  Network net(model(hashgrid(2, 2, 4, 2)));
  ASSERT_EQ(net.grid_params(), v["n_params"].get<uint64_t>());
  for (auto& lv : v["levels"]) {
    const GridLevel& L = net.grid().levels[lv["level"].get<int>()];
    EXPECT_EQ(L.scale, lv["scale"].get<float>());
    EXPECT_EQ(L.res, lv["resolution"].get<uint32_t>());
    EXPECT_EQ(L.n_entries, lv["entries"].get<uint32_t>());
    EXPECT_EQ(L.offset, lv["offset"].get<uint32_t>());
    EXPECT_EQ(bool(L.hashed), lv["hashed"].get<bool>());
  }
}

TEST(GridEncoding, CornersWeightsAndFeaturesBitExact) {
  Json v = vectors();
  for (std::string interp : {"linear", "smoothstep"}) {
    Network net(model(hashgrid(2, 2, 4, 2, interp == "linear" ? "Linear" : "Smoothstep")));
    net.edit_params([&](float* p, size_t) {  // multiples of 1/64: exact in fp16
      float* table = p + net.mlp().n_params;
      for (uint64_t k = 0; k < net.grid_params(); ++k) table[k] = float((int64_t(k) * 37) % 101 - 50) / 64.0f;
    });
    for (auto& pt : v["points"]) {
      float x[3];
      for (int d = 0; d < 3; ++d) x[d] = pt["input"][d].get<float>();
      float feat[4];
      net.encode_point(x, feat);
      for (auto& lv : pt[interp]) {
        int l = lv["level"].get<int>();
        GridCorners c;
        grid_corners(net.grid().levels[l], net.grid().interpolation, x[0], x[1], x[2], c);
        for (auto& cj : lv["corners"]) {
          int k = cj["corner_bits"].get<int>();
          EXPECT_EQ(bits(c.weight[k]), std::stoul(cj["weight_hex"].get<std::string>(), nullptr, 16))
              << interp << " level " << l << " corner " << k;
          EXPECT_EQ(c.entry[k], cj["entry"].get<uint32_t>());
          EXPECT_EQ((net.grid().levels[l].offset + c.entry[k]) * 2, cj["param_index"].get<uint32_t>());
        }
        for (int f = 0; f < 2; ++f) EXPECT_EQ(feat[l * 2 + f], lv["features"][f].get<float>()) << interp;
      }
      // The chunk kernel used in training must agree exactly with the per-point path.
      float xs[16], ys[16], zs[16];
      for (int s = 0; s < 16; ++s) xs[s] = x[0], ys[s] = x[1], zs[s] = x[2];
      std::vector<float> X0(net.mlp().in_pad * 16);
      net.encode(xs, ys, zs, 16, X0.data());
      for (int j = 0; j < 4; ++j) EXPECT_EQ(X0[j * 16 + 5], feat[j]);
      for (uint32_t j = 4; j < net.mlp().in_pad; ++j) EXPECT_EQ(X0[j * 16], 0.0f);  // grid padding is 0
    }
  }
}

TEST(GridEncoding, HashVectors) {
  Json v = vectors();
  GridLevel L;
  L.hashed = 1;
  L.n_entries = 1u << 19;
  L.pow2_mask = L.n_entries - 1;
  for (auto& h : v["hashes"]) {
    uint32_t x = h["coords"][0], y = h["coords"][1], z = h["coords"][2];
    EXPECT_EQ(grid_entry(L, x, y, z), h["mod_2_19"].get<uint32_t>());
  }
}

TEST(GridEncoding, UniformFillMatchesVectors) {
  Json v = vectors();
  Pcg32 rng(seed_seq_first_word(1337));
  float out[8];
  tcnn_uniform_fill(rng, out, 8, -1e-4f, 1e-4f);
  // grid_vectors.py evaluates the fma with the bounds as binary64 (-1e-4, not -1e-4f), while tcnn
  // (and vnr) use binary32 bounds, so the last bits may differ.
  for (int i = 0; i < 8; ++i) {
    float e = v["rng"]["gpu_uniform_fill_8_pm1e4"][i].get<float>();
    EXPECT_NEAR(out[i], e, 1e-11) << i;
  }
  Pcg32 ref(seed_seq_first_word(1337));
  ref.advance(8);
  EXPECT_EQ(rng.next_uint(), ref.next_uint());
}

struct CountCase {
  const char* name;
  Json cfg;
  uint64_t total;
};

TEST(ParamCount, PaperAppendixConfigs) {
  Network paper(preset_config("paper"));
  EXPECT_EQ(paper.grid().n_entries, 1872448u);
  EXPECT_EQ(paper.n_params(), 14996992u);
  EXPECT_NEAR(paper.n_params() * 2.0 / (1 << 20), 28.6, 0.05);  // MiB in fp16
  const CountCase cases[] = {
      {"rm_t60", model(hashgrid(2, 8, 15, 32), "FullyFusedMLP", 32, 3), 527360},
      {"supernova", model(hashgrid(8, 8, 17, 4), "FullyFusedMLP", 64, 2), 4503040},
      {"1atmTemp", model(hashgrid(10, 8, 19, 4), "FullyFusedMLP", 64, 3), 23382528},
      {"chameleon", model(hashgrid(8, 8, 19, 4), "FullyFusedMLP", 64, 3), 14992896},
      {"10atmTemp", model(hashgrid(10, 8, 19, 4), "FullyFusedMLP", 64, 4), 23386624},
      // Ablation configs (pinned tcnn: CutlassMLP aligns to 8).
      {"identity", model({{"otype", "Identity"}}, "CutlassMLP", 256, 15), 921600},
      {"oneblob", model({{"otype", "OneBlob"}, {"n_bins", 64}}, "CutlassMLP", 256, 14), 903168},
      {"frequency", model({{"otype", "Frequency"}, {"n_frequencies", 32}}, "CutlassMLP", 256, 14), 903168},
      {"densegrid", model(hashgrid(2, 2, 19, 37, "Linear", "DenseGrid"), "CutlassMLP", 64, 4), 925072},
      {"hashgrid", model(hashgrid(8, 4, 15, 14), "CutlassMLP", 64, 4), 900064},
  };
  for (auto& c : cases) EXPECT_EQ(Network(c.cfg).n_params(), c.total) << c.name;
}

TEST(ParamCount, MlpLayoutOffsets) {
  Network net(preset_config("paper"));
  const MlpLayout& m = net.mlp();
  EXPECT_EQ(m.in_pad, 64u);
  EXPECT_EQ(m.out_pad, 16u);
  EXPECT_EQ(m.n_params, 17408u);
  EXPECT_EQ(m.offset[1], 64u * 64u);
  EXPECT_EQ(m.offset[4], 64u * 64u + 3u * 64u * 64u);
}

// d(sum_j G_j enc_j) / d theta: analytic (grid backward) vs central differences. The encoding is
// linear in theta, so differences are exact up to rounding.
TEST(GridEncoding, ParameterGradientMatchesFiniteDifferences) {
  for (std::string interp : {"Linear", "Smoothstep", "Nearest"})
    for (int F : {1, 2, 4, 8})
      for (std::string otype : {"HashGrid", "DenseGrid"}) {
        Network net(model(hashgrid(3, F, 8, 3, interp, otype)));
        net.init_params(7);
        std::mt19937 gen(3);
        std::uniform_real_distribution<float> U(0.f, 1.f);
        // Multiples of 2^-10 in [-0.5, 0.5] and steps of 0.25 stay exact in the fp16 working copy.
        net.edit_params([&](float* p, size_t) {
          float* table = p + net.mlp().n_params;
          for (uint64_t k = 0; k < net.grid_params(); ++k) table[k] = std::round((U(gen) - 0.5f) * 1024) / 1024;
        });
        const int n = kChunk;
        std::vector<float> x(n), y(n), z(n), dEnc(net.mlp().in_pad * n);
        for (int s = 0; s < n; ++s) x[s] = U(gen), y[s] = U(gen), z[s] = U(gen);
        for (auto& g : dEnc) g = U(gen) - 0.5f;
        std::vector<float> grad(net.grid_params(), 0.0f);
        for (uint32_t l = 0; l < net.grid().n_levels; ++l)
          net.grid_backward_level(l, x.data(), y.data(), z.data(), n, dEnc.data(), n, grad.data());
        auto objective = [&]() {
          std::vector<float> X0(net.mlp().in_pad * n);
          net.encode(x.data(), y.data(), z.data(), n, X0.data());
          double acc = 0;
          for (uint32_t j = 0; j < net.mlp().enc_width; ++j)
            for (int s = 0; s < n; ++s) acc += double(X0[j * n + s]) * dEnc[j * n + s];
          return acc;
        };
        std::uniform_int_distribution<uint64_t> pick(0, net.grid_params() - 1);
        for (int trial = 0; trial < 40; ++trial) {
          uint64_t k = pick(gen);
          const uint64_t at = net.mlp().n_params + k;
          const float keep = net.params()[at];
          const float h = 0.25f;
          auto set = [&](float v) { net.edit_params([&](float* p, size_t) { p[at] = v; }); };
          set(keep + h);
          double fp = objective();
          set(keep - h);
          double fm = objective();
          set(keep);
          double fd = (fp - fm) / (2 * h);
          EXPECT_NEAR(grad[k], fd, 1e-4 + 1e-4 * std::fabs(fd)) << otype << " F=" << F << " " << interp << " k=" << k;
        }
      }
}

// d enc / d x for every encoding type against central differences at points away from lattice
// boundaries (where the grid encodings are not differentiable).
TEST(Encodings, InputGradientMatchesFiniteDifferences) {
  const Json encs[] = {hashgrid(3, 2, 10, 4),
                       hashgrid(2, 4, 10, 3, "Smoothstep", "DenseGrid"),
                       {{"otype", "Frequency"}, {"n_frequencies", 6}},
                       {{"otype", "OneBlob"}, {"n_bins", 8}},
                       {{"otype", "Identity"}, {"scale", 2.0}, {"offset", 0.5}}};
  for (const Json& e : encs) {
    Network net(model(e));
    net.init_params(1);
    std::mt19937 gen(11);
    std::uniform_real_distribution<float> U(-1.f, 1.f);
    net.edit_params([&](float* p, size_t) {
      float* table = p + net.mlp().n_params;
      for (uint64_t k = 0; k < net.grid_params(); ++k) table[k] = U(gen);
    });
    const uint32_t w = net.mlp().enc_width;
    std::vector<float> jac(w * 3), fp(w), fm(w);
    const float pts[3][3] = {{0.31f, 0.47f, 0.59f}, {0.123f, 0.77f, 0.41f}, {0.66f, 0.21f, 0.83f}};
    for (auto& p0 : pts) {
      net.encode_point_input_grad(p0, jac.data());
      for (int d = 0; d < 3; ++d) {
        const float h = 1e-3f;
        float p[3] = {p0[0], p0[1], p0[2]};
        p[d] = p0[d] + h;
        net.encode_point(p, fp.data());
        p[d] = p0[d] - h;
        net.encode_point(p, fm.data());
        for (uint32_t j = 0; j < w; ++j) {
          float fd = (fp[j] - fm[j]) / (2 * h);
          EXPECT_NEAR(jac[j * 3 + d], fd, 2e-2 + 2e-3 * std::fabs(fd)) << e.dump() << " j=" << j << " d=" << d;
        }
      }
    }
  }
}

TEST(Encodings, FrequencyAndOneBlobValues) {
  Network f(model({{"otype", "Frequency"}, {"n_frequencies", 2}}));
  float x[3] = {0.25f, 0.5f, 0.0f}, out[12];
  f.encode_point(x, out);
  // dim 0 block: sin(pi x), cos(pi x), sin(2 pi x), cos(2 pi x)
  EXPECT_NEAR(out[0], std::sin(M_PI * 0.25), 1e-6);
  EXPECT_NEAR(out[1], std::cos(M_PI * 0.25), 1e-6);
  EXPECT_NEAR(out[2], 1.0, 1e-6);
  EXPECT_NEAR(out[3], 0.0, 1e-6);
  EXPECT_NEAR(out[8], 0.0, 1e-6);  // dim 2, sin(0)
  // OneBlob: a partition of unity over the bins of each dim.
  Network ob(model({{"otype", "OneBlob"}, {"n_bins", 16}}));
  float y[3] = {0.3f, 0.01f, 0.97f}, o[48];
  ob.encode_point(y, o);
  for (int d = 0; d < 3; ++d) {
    double sum = 0;
    for (int b = 0; b < 16; ++b) {
      EXPECT_GE(o[d * 16 + b], -1e-6f);
      sum += o[d * 16 + b];
    }
    EXPECT_NEAR(sum, 1.0, 1e-5);
  }
  // Parameter-free encodings pad with 1.0 (a bias input for the first layer).
  Network id(model({{"otype", "Identity"}}));
  EXPECT_EQ(id.mlp().in_pad, 16u);
  EXPECT_EQ(id.mlp().pad_value, 1.0f);
}

TEST(Config, UnsupportedValuesListAllowed) {
  auto msg = [](Json cfg) {
    try {
      Network n(cfg);
    } catch (const std::exception& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(msg(model({{"otype", "TriangleWave"}})).find("allowed: HashGrid"), std::string::npos);
  EXPECT_NE(msg(model(hashgrid(2, 3, 10, 4))).find("1, 2, 4 or 8"), std::string::npos);
  EXPECT_NE(msg(model({{"otype", "OneBlob"}, {"n_bins", 2048}})).find("1..1024"), std::string::npos);
  EXPECT_NE(msg(model({{"otype", "Frequency"}, {"n_frequencies", 33}})).find("1..32"), std::string::npos);
  EXPECT_NE(msg(model(hashgrid(2, 2, 10, 4), "FullyFusedMLP", 48)).find("16, 32, 64 or 128"), std::string::npos);
  EXPECT_NE(msg(model(hashgrid(2, 2, 10, 4), "ResNet")).find("allowed: FullyFusedMLP"), std::string::npos);
  Json bad_loss = model(hashgrid(2, 2, 10, 4));
  bad_loss["loss"] = {{"otype", "Huber"}};
  EXPECT_NE(msg(bad_loss).find("allowed: L1, L2, RelativeL2"), std::string::npos);
  Json bad_opt = model(hashgrid(2, 2, 10, 4));
  bad_opt["optimizer"] = {{"otype", "SGD"}};
  EXPECT_NE(msg(bad_opt).find("allowed: Adam, ExponentialDecay"), std::string::npos);
  // Case-insensitive otype and the paper's {"params": {...}} wrapper.
  Json wrapped = {{"params", model(hashgrid(2, 2, 10, 4, "linear", "hashgrid"))}};
  EXPECT_EQ(msg(wrapped), "");
}

TEST(Config, RoundTripThroughJson) {
  Network a(preset_config("paper"));
  Network b(a.config_json());
  EXPECT_EQ(a.config_json(), b.config_json());
  EXPECT_EQ(a.config().adam.epsilon, 1e-15f);
  EXPECT_TRUE(a.config().decay.enabled);
  EXPECT_EQ(a.config().decay.decay_start, 2000u);
}

// The instantvnr example config (with // comments) parses and gives the documented count.
TEST(Config, InstantvnrExampleModel) {
  std::string path = std::string(VNR_SHARED_DIR) + "/reference/instantvnr-formats/examples/example-model.json";
  if (!file_exists(path)) GTEST_SKIP() << "../shared absent";
  Network n(parse_json_file(path));
  EXPECT_EQ(n.n_params(), 23380992u);
}

// Every SIMD target this machine supports (AVX-512, AVX2, SSE4, ...) encodes, scatters gradients and
// looks up the ground truth bit-identically to the per-point reference functions: the paper config
// (F = 8, dense and hashed levels), the small one (F = 2, every level dense: the x-pair gather path)
// and F = 2 with smoothstep. A quarter of the points lie on the cube's faces and far corner, where
// dense corners alias into the next row and an x-pair can straddle the table's end.
TEST(GridEncoding, EverySimdTargetIsBitIdentical) {
  for (const Json& cfg : {preset_config("paper"), preset_config("small"), model(hashgrid(5, 2, 14, 3, "Smoothstep"))}) {
    SCOPED_TRACE(cfg.dump());
    Network net(cfg);
    net.init_params(3);
    std::mt19937 gen(5);
    std::uniform_real_distribution<float> U(0.f, 1.f);
    net.edit_params([&](float* p, size_t) {
      float* table = p + net.mlp().n_params;
      for (uint64_t k = 0; k < net.grid_params(); ++k) table[k] = (U(gen) - 0.5f) * 0.5f;
    });
    const int n = kChunk;
    std::vector<float> x(n), y(n), z(n), dEnc(size_t(net.mlp().in_pad) * n);
    for (int s = 0; s < n; ++s) {
      x[s] = U(gen), y[s] = U(gen), z[s] = U(gen);
      if (s % 4 == 1) x[s] = 1.0f, y[s] = s % 8 == 1 ? 1.0f : y[s], z[s] = s % 16 == 1 ? 1.0f : 0.97f + 0.03f * z[s];
    }
    for (auto& g : dEnc) g = U(gen) - 0.5f;
    std::vector<float> ref_X0(size_t(net.mlp().enc_width) * n);
    for (int s = 0; s < n; ++s) {
      const float p[3] = {x[s], y[s], z[s]};
      std::vector<float> f(net.mlp().enc_width);
      net.encode_point(p, f.data());
      for (uint32_t j = 0; j < net.mlp().enc_width; ++j) ref_X0[j * n + s] = f[j];
    }
    // The gradient scatter's reference: the per-point function, sample by sample (dEnc's chunk is n).
    std::vector<float> ref_grad(net.grid_params(), 0.0f);
    const GridLayout& g = net.grid();
    for (uint32_t l = 0; l < g.n_levels; ++l)
      for (int s = 0; s < n; ++s) {
        const float* dy = dEnc.data() + size_t(l) * g.n_features * n + s;
        switch (g.n_features) {
          case 2: grid_level_backward<2>(g.levels[l], g.interpolation, ref_grad.data(), x[s], y[s], z[s], dy, n); break;
          case 8: grid_level_backward<8>(g.levels[l], g.interpolation, ref_grad.data(), x[s], y[s], z[s], dy, n); break;
          default: FAIL();
        }
      }
    for (int64_t t : hwy::SupportedAndGeneratedTargets()) {
      hwy::SetSupportedTargetsForTest(t);
      SCOPED_TRACE(hwy::TargetName(t));
      std::vector<float> X0(size_t(net.mlp().in_pad) * n);
      net.encode(x.data(), y.data(), z.data(), n, X0.data());
      for (size_t i = 0; i < ref_X0.size(); ++i) ASSERT_EQ(X0[i], ref_X0[i]) << i;
      std::vector<float> grad(net.grid_params(), 0.0f);
      for (uint32_t l = 0; l < net.grid().n_levels; ++l)
        net.grid_backward_level(l, x.data(), y.data(), z.data(), n, dEnc.data(), n, grad.data());
      ASSERT_EQ(grad, ref_grad);
    }
    hwy::SetSupportedTargetsForTest(0);
  }
}
