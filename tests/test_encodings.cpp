// Encodings as objects (nn/encoding.h): the otype registry, each encoding's describe-back JSON, its
// per-point evaluation against the chunk forward; and Adam's shared update (nn/adam_update.h) against
// the vectorised CPU kernel, bit for bit on every SIMD target.
#include <gtest/gtest.h>
#include <hwy/targets.h>
#include <cfloat>
#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <vector>
#include "vnr/error.h"
#include "vnr/core/half.h"
#include "vnr/nn/adam_update.h"
#include "vnr/nn/cpu_kernels.h"
#include "vnr/nn/encoding.h"
#include "vnr/nn/network.h"
#include "test_support.h"

using namespace vnr;
using vnr::test::bits;

namespace {

// One encoding object of every registered otype (and the grid's interpolations).
std::vector<Json> every_encoding() {
  return {
      {{"otype", "HashGrid"}, {"n_levels", 4}, {"n_features_per_level", 2}, {"log2_hashmap_size", 12},
       {"base_resolution", 4}, {"per_level_scale", 1.5}},
      {{"otype", "DenseGrid"}, {"n_levels", 2}, {"n_features_per_level", 4}, {"base_resolution", 3},
       {"interpolation", "Smoothstep"}},
      {{"otype", "TiledGrid"}, {"n_levels", 3}, {"n_features_per_level", 1}, {"base_resolution", 5},
       {"interpolation", "Nearest"}},
      {{"otype", "Grid"}, {"type", "Hash"}, {"n_levels", 2}, {"n_features_per_level", 8}, {"log2_hashmap_size", 10}},
      {{"otype", "Frequency"}, {"n_frequencies", 5}},
      {{"otype", "OneBlob"}, {"n_bins", 8}},
      {{"otype", "Identity"}, {"scale", 0.5}, {"offset", -0.25}},
  };
}

Json model(const Json& enc) {
  return Json{{"encoding", enc},
              {"network", {{"otype", "FullyFusedMLP"}, {"n_neurons", 16}, {"n_hidden_layers", 1}}},
              {"loss", {{"otype", "L1"}}}};
}

std::string error_of(const Json& enc) {
  try {
    parse_encoding_config(enc);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(EncodingRegistry, CreatesEveryOtype) {
  const std::vector<std::pair<std::string, uint32_t>> expected_width = {
      {"HashGrid", 8}, {"DenseGrid", 8}, {"TiledGrid", 3}, {"Grid", 16}, {"Frequency", 30}, {"OneBlob", 24},
      {"Identity", 3}};
  const std::vector<Json> encs = every_encoding();
  ASSERT_EQ(encs.size(), expected_width.size());
  for (size_t i = 0; i < encs.size(); ++i) {
    SCOPED_TRACE(encs[i].dump());
    const EncodingConfig e = parse_encoding_config(encs[i]);
    const std::unique_ptr<Encoding> enc = make_encoding(e);
    EXPECT_EQ(enc->output_width(), expected_width[i].second);
    const bool grid = i < 4;
    EXPECT_EQ(enc->grid() != nullptr, grid);
    EXPECT_EQ(enc->n_params() > 0, grid);
    EXPECT_EQ(enc->pad_value(), grid ? 0.0f : 1.0f);
    EXPECT_EQ(enc->n_backward_parts(), grid ? e.n_levels : 0u);
    // The Network sizes its encoding block from the same object.
    Network net(model(encs[i]));
    EXPECT_EQ(net.grid_params(), enc->n_params());
    EXPECT_EQ(net.mlp().enc_width, enc->output_width());
    EXPECT_EQ(net.has_grid(), grid);
  }
  // Case-insensitive otype names, as tiny-cuda-nn's.
  EXPECT_EQ(parse_encoding_config({{"otype", "hashgrid"}}).type, EncodingType::Grid);
  EXPECT_EQ(parse_encoding_config({{"otype", "ONEBLOB"}}).type, EncodingType::OneBlob);
}

TEST(EncodingRegistry, UnknownOtypeListsTheAllowedOnes) {
  const std::string msg = error_of({{"otype", "TriangleWave"}});
  EXPECT_NE(msg.find("unsupported otype 'TriangleWave'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("(allowed: HashGrid, DenseGrid, TiledGrid, Grid, Frequency, OneBlob, Identity)"),
            std::string::npos)
      << msg;
  EXPECT_EQ(encoding_registry().allowed_otypes(), "HashGrid, DenseGrid, TiledGrid, Grid, Frequency, OneBlob, Identity");
  EXPECT_NE(error_of({{"otype", "OneBlob"}, {"n_bins", 12}}).find("power of two"), std::string::npos);
  EXPECT_NE(error_of({{"otype", "Frequency"}, {"n_frequencies", "many"}}).find("'n_frequencies' must be a number"),
            std::string::npos);
  EXPECT_NE(error_of(Json::array()).find("'encoding' must be an object"), std::string::npos);
}

TEST(EncodingRegistry, DescribeBackRoundTrips) {
  for (const Json& j : every_encoding()) {
    SCOPED_TRACE(j.dump());
    const EncodingConfig e = parse_encoding_config(j);
    const Json described = make_encoding(e)->to_json();
    // Every key explicit, and what is described parses back to the same description.
    const Json again = make_encoding(parse_encoding_config(described))->to_json();
    EXPECT_EQ(described.dump(), again.dump());
    // The config's JSON (model files, config_json()) carries the same object.
    Network net(model(j));
    EXPECT_EQ(net.config_json().at("encoding").dump(), described.dump());
    EXPECT_EQ(net.encoding().to_json().dump(), described.dump());
  }
}

TEST(Encodings, PointEvaluationEqualsChunkForward) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-0.1f, 1.1f);
  const int n = 37;
  std::vector<float> x(n), y(n), z(n);
  for (int i = 0; i < n; ++i) x[i] = u(rng), y[i] = u(rng), z[i] = u(rng);
  for (const Json& j : every_encoding()) {
    SCOPED_TRACE(j.dump());
    Network net(model(j));
    net.init_params(3);
    net.edit_params([&](float* p, size_t) {
      float* table = p + net.mlp().n_params;
      for (uint64_t k = 0; k < net.grid_params(); ++k) table[k] = float(int64_t(k * 37 % 101) - 50) / 64.0f;
    });
    const MlpLayout& m = net.mlp();
    std::vector<float> X0(size_t(m.in_pad) * n), point(m.enc_width);
    net.encode(x.data(), y.data(), z.data(), n, X0.data());
    int mismatches = 0;
    for (int s = 0; s < n; ++s) {
      const float p[3] = {x[s], y[s], z[s]};
      net.encoding().encode_point(p, net.grid_half(), point.data());
      for (uint32_t f = 0; f < m.enc_width; ++f) mismatches += bits(point[f]) != bits(X0[size_t(f) * n + s]);
      for (uint32_t f = m.enc_width; f < m.in_pad; ++f) mismatches += X0[size_t(f) * n + s] != m.pad_value;
    }
    EXPECT_EQ(mismatches, 0);
  }
}

// The Highway kernel against adam_update() applied element by element, matrix and lazy (grid) ranges.
TEST(Adam, VectorKernelEqualsSharedUpdateBitExact) {
  const int64_t n = 1000 + 3;  // a tail past the last full vector
  std::vector<float> bias_sqrt(8), bias_den(8);
  for (int c = 1; c < 8; ++c) {
    bias_sqrt[c] = std::sqrt(1.0f - std::pow(0.99f, float(c)));
    bias_den[c] = 1.0f - std::pow(0.9f, float(c));
  }
  for (int64_t target : hwy::SupportedAndGeneratedTargets()) {
    hwy::SetSupportedTargetsForTest(target);
    SCOPED_TRACE(hwy::TargetName(target));
    // Targets without F16C demote to fp16 in software, which rounds differently from float_to_half for
    // some values: the half copy is compared where the CPU converts in hardware.
    const std::string name = hwy::TargetName(target);
    const bool hardware_f16 = name != "SSE4" && name != "SSSE3" && name != "SSE2" && name != "EMU128" && name != "SCALAR";
    for (bool matrix : {true, false}) {
      for (bool adabound : {false, true}) {
        std::mt19937 rng(11);
        std::normal_distribution<float> g(0.0f, 1.0f);
        std::vector<float> w(n), grads(n), m(n), v(n);
        std::vector<uint32_t> c(n);
        for (int64_t i = 0; i < n; ++i) {
          w[i] = g(rng), m[i] = 0.1f * g(rng), v[i] = std::abs(0.01f * g(rng)), c[i] = uint32_t(i % 5);
          grads[i] = i % 7 == 3 ? 0.0f : g(rng);  // zero gradients: skipped when not matrix
        }
        kernels::AdamStep k{{0.01f, 0.9f, 0.99f, 1e-8f, 1e-4f, 0.01f, 1e-3f, adabound ? 0.05f : 0.0f,
                             adabound ? 0.2f : FLT_MAX},
                            matrix,
                            bias_sqrt.data(),
                            bias_den.data()};
        std::vector<float> rw = w, rm = m, rv = v, rg = grads;
        std::vector<uint32_t> rc = c;
        std::vector<uint16_t> half(n);
        kernels::adam_range(k, w.data(), grads.data(), m.data(), v.data(), c.data(), half.data(), n);
        int mismatches = 0;
        for (int64_t i = 0; i < n; ++i) {
          const bool updated = matrix || rg[i] != 0.0f;  // skipped ones keep their (unwritten) half
          if (updated) {
            const uint32_t ci = ++rc[i];
            adam_update(k, matrix, rg[i], bias_sqrt[ci], bias_den[ci], rw[i], rm[i], rv[i]);
          }
          const bool bad = bits(w[i]) != bits(rw[i]) || bits(m[i]) != bits(rm[i]) || bits(v[i]) != bits(rv[i]) ||
                           c[i] != rc[i] || grads[i] != 0.0f ||
                           (updated && hardware_f16 && half[i] != float_to_half(rw[i]));
          if (bad && mismatches < 3)
            ADD_FAILURE() << "i " << i << " w " << w[i] << " " << rw[i] << " m " << m[i] << " " << rm[i] << " v " << v[i]
                          << " " << rv[i] << " half " << half[i] << " " << float_to_half(rw[i]);
          mismatches += bad;
        }
        EXPECT_EQ(mismatches, 0) << "matrix " << matrix << " adabound " << adabound;
      }
    }
  }
  hwy::SetSupportedTargetsForTest(0);
}
