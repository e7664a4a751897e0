// The CDF 9/7 wavelet (volume/wavelet.h) against its closed-form properties, and wavelet residuals
// (train/residual_wavelet.cpp): they fill a budget, keep the bound they record at every voxel, survive
// a model file, are chosen only where they decode closer, and a damaged block is one clear error.
#include <random>
#include "test_support.h"
#include "vnr/api/model_field.h"
#include "vnr/core/rng.h"
#include "vnr/fields/brick_cache.h"
#include "vnr/model.h"
#include "vnr/train/residual_context_coder.h"
#include "vnr/train/residuals.h"
#include "vnr/volume/wavelet.h"

using namespace vnr;
using namespace vnr::test;

namespace {

std::vector<float> noise(Int3 dims, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> n(0, 1);
  std::vector<float> v(size_t(dims.count()));
  for (float& x : v) x = n(rng);
  return v;
}

double sum_of_squares(const std::vector<float>& v) {
  double s = 0;
  for (float x : v) s += double(x) * double(x);
  return s;
}

}  // namespace

TEST(Wavelet, LevelsSplitAxesOfAtLeastEightSamples) {
  EXPECT_EQ(wavelet_levels({256, 256, 256}), kWaveletMaxLevels);  // 256 -> 8 in five halvings
  EXPECT_EQ(wavelet_levels({91, 91, 91}), 4);                      // 91, 46, 23, 12 split; 6 does not
  EXPECT_EQ(wavelet_levels({9, 1, 30}), 3);                        // z: 30, 15, 8 split; x: 9 once
  EXPECT_EQ(wavelet_levels({7, 7, 7}), 0);
}

TEST(Wavelet, InverseUndoesForwardOnOddAndFlatGrids) {
  for (Int3 dims : {Int3{21, 18, 13}, Int3{9, 1, 30}, Int3{64, 8, 8}}) {
    SCOPED_TRACE(testing::Message() << dims.x << "x" << dims.y << "x" << dims.z);
    const std::vector<float> original = noise(dims, 5);
    std::vector<float> v = original;
    const int levels = wavelet_levels(dims);
    wavelet_forward(v, dims, levels);
    EXPECT_GT(max_abs_diff(v, original), 0.1);  // it did transform
    wavelet_inverse(v, dims, levels);
    EXPECT_LT(max_abs_diff(v, original), 2e-5);
  }
}

// With low *= K and high /= K the transform is nearly orthonormal (biorthogonal, not exactly): white
// noise keeps its energy within about 10 %, so an error in the coefficients is about that in the voxels.
TEST(Wavelet, WhiteNoiseKeepsItsEnergy) {
  const Int3 dims{32, 32, 32};
  std::vector<float> v = noise(dims, 9);
  const double before = sum_of_squares(v);
  wavelet_forward(v, dims, wavelet_levels(dims));
  EXPECT_NEAR(sum_of_squares(v) / before, 1.0, 0.12);
}

// Four vanishing moments: a cubic along x has no detail coefficients away from the ends (where the
// symmetric extension bends it), and a constant none at all.
TEST(Wavelet, PolynomialsUpToCubicsHaveNoDetail) {
  const Int3 dims{64, 4, 4};  // only x splits
  std::vector<float> cubic(size_t(dims.count())), constant(size_t(dims.count()), 0.75f);
  for (int64_t i = 0; i < dims.count(); ++i) {
    const double x = double(i % dims.x) / 64;
    cubic[size_t(i)] = float(0.2 + 0.5 * x - 0.3 * x * x + 0.4 * x * x * x);
  }
  wavelet_forward(cubic, dims, 1);
  wavelet_forward(constant, dims, 1);
  for (int64_t i = 0; i < dims.count(); ++i) {
    const int64_t x = i % dims.x;
    if (x < 32) continue;  // the low band
    EXPECT_NEAR(constant[size_t(i)], 0.0, 1e-6) << x;
    if (x >= 35 && x < 61) EXPECT_NEAR(cubic[size_t(i)], 0.0, 2e-6) << x;
  }
  EXPECT_GT(std::fabs(cubic[63]), 1e-4);  // the far end's extension is not a cubic
}

namespace {

const Int3 kDims{40, 36, 30};

Model model_for(Int3 dims) {
  return create_model(ModelConfig::from_json(small_hash_config(10, 16, 1)), dims, DType::Float32, 0, 1, 3);
}

std::vector<float> decode(const Model& m) {
  std::vector<float> out(size_t(m.dims.count()));
  ModelQuery(m, Device::Cpu).slab(m.dims, 0, m.dims.z, out.data());
  return out;
}

}  // namespace

// A smooth field with a sharp ridge: the wavelet spends the budget on the ridge and decodes closer than
// voxel residuals of the same size; the bound it records holds at every voxel, also after a file.
TEST(WaveletResiduals, FillTheBudgetAndKeepTheirBoundThroughAFile) {
  Volume vol = make_volume(kDims, [](float x, float y, float z) {
    return 0.5f + 0.3f * std::sin(6 * x) * std::cos(5 * y) + (std::fabs(z - 0.5f) < 0.05f ? 0.15f : 0.f);
  });
  Model m = model_for(kDims);
  const uint64_t budget = 3000;
  const Residuals r = residuals_for_budget(*m.net, vol.data.data(), kDims, budget);
  ASSERT_TRUE(r.wavelet()) << r.encoded->meta.dump();
  EXPECT_LE(r.encoded->bytes.size(), budget);
  EXPECT_GE(double(r.encoded->bytes.size()), 0.9 * double(budget));
  const Json& errors = r.encoded->meta["candidate_squared_error"];
  EXPECT_LT(errors["wavelet"].get<double>(), errors["voxels"].get<double>());
  Model with = model_for(kDims);
  with.residuals = r;
  const std::vector<float> decoded = decode(with);
  EXPECT_LE(max_abs_diff(decoded, vol.data), r.bound);
  EXPECT_GT(max_abs_diff(decoded, vol.data), 0.9 * (r.bound - residual_margin(r.bound)));  // measured, not loose

  TmpDir dir;
  save_model(dir / "w.vnr", with);
  const Model loaded = load_model(dir / "w.vnr");
  ASSERT_TRUE(loaded.residuals && loaded.residuals->wavelet());
  EXPECT_EQ(loaded.residuals->q, r.q);
  const std::vector<float> again = decode(loaded);
  for (size_t i = 0; i < again.size(); ++i) ASSERT_EQ(bits(again[i]), bits(decoded[i])) << i;
}

// Non-zero coefficients are rebuilt at their bins' means per level: each offset is that mean (to 1e-3),
// and it decodes closer than the bins' lower ends (q step) would.
TEST(WaveletResiduals, CoefficientsAreRebuiltAtTheirBinsMeans) {
  Volume vol = make_volume(kDims, [](float x, float y, float z) {
    return 0.5f + 0.3f * std::sin(6 * x) * std::cos(5 * y) + (std::fabs(z - 0.5f) < 0.05f ? 0.15f : 0.f);
  });
  const std::optional<Residuals> r = wavelet_residuals_for_budget(vol.data.data(), nullptr, kDims, 3000);
  ASSERT_TRUE(r);
  ASSERT_EQ(r->wavelet_offsets.size(), size_t(r->wavelet_levels) + 1);
  std::vector<float> c(vol.data.begin(), vol.data.end());
  wavelet_forward(c, kDims, r->wavelet_levels);
  const std::vector<uint8_t> level = wavelet_coefficient_levels(kDims, r->wavelet_levels);
  std::vector<double> sum(r->wavelet_offsets.size(), 0.0), count(sum.size(), 0.0);
  for (size_t i = 0; i < c.size(); ++i)
    if (r->q[i] != 0) sum[level[i]] += std::fabs(c[i]) / r->step - std::abs(r->q[i]), count[level[i]] += 1;
  for (size_t l = 0; l < sum.size(); ++l)
    if (count[l] > 0) EXPECT_NEAR(r->wavelet_offsets[l], sum[l] / count[l], 5e-4 + 1e-9) << l;
  Residuals plain = *r;
  plain.wavelet_offsets.clear();
  invert_wavelet_residuals(plain);
  EXPECT_LT(residual_error_stats(*r, vol.data.data(), nullptr).mse, residual_error_stats(plain, vol.data.data(), nullptr).mse);
}

// Coefficient levels in the Mallat layout: the low band is the last level's box, level 0 all but the
// first level's box (40 x 36 x 30 -> 20 x 18 x 15 -> 10 x 9 x 8 -> 5 x 9 x 4: y and z stop at 9 and 8).
TEST(Wavelet, CoefficientLevelsFollowTheBoxes) {
  ASSERT_EQ(wavelet_levels(kDims), 3);
  const std::vector<uint8_t> level = wavelet_coefficient_levels(kDims, 3);
  auto count = [&](int l) { return std::count(level.begin(), level.end(), uint8_t(l)); };
  EXPECT_EQ(count(3), 5 * 5 * 4);
  EXPECT_EQ(count(2), 10 * 9 * 8 - 5 * 5 * 4);
  EXPECT_EQ(count(1), 20 * 18 * 15 - 10 * 9 * 8);
  EXPECT_EQ(count(0), 40 * 36 * 30 - 20 * 18 * 15);
  EXPECT_EQ(level[0], 3);
  EXPECT_EQ(level[size_t(kDims.count()) - 1], 0);
}

// Isolated spikes: one voxel residual each, where a wavelet spreads every spike over its supports.
TEST(WaveletResiduals, SpikesKeepVoxelResiduals) {
  std::vector<float> v(size_t(kDims.count()), 0.5f);
  Pcg32 rng(3);
  for (float& x : v)
    if (rng.next_float() < 0.01f) x = rng.next_float() < 0.5f ? 0.1f : 0.9f;
  const Volume vol = make_volume(kDims, v);
  Model m = model_for(kDims);
  const Residuals r = residuals_for_budget(*m.net, vol.data.data(), kDims, 4000);
  EXPECT_FALSE(r.wavelet());
  const Json& errors = r.encoded->meta["candidate_squared_error"];
  EXPECT_LE(errors["voxels"].get<double>(), errors["wavelet"].get<double>());
}

TEST(WaveletResiduals, DamagedBlocksAreOneClearError) {
  Residuals r;
  r.dims = kDims;
  r.step = 0.01;
  r.bound = 0.5;
  r.wavelet_levels = wavelet_levels(kDims);
  r.q = std::vector<int32_t>(size_t(kDims.count()), 0);
  r.q[0] = 40, r.q[7] = -3, r.q[size_t(kDims.count()) - 1] = 1;
  const EncodedResiduals e = encode_residuals(r);
  EXPECT_FALSE(e.meta.contains("offsets"));  // as files before the offsets: rebuilt at q step
  const Residuals back = decode_residuals(e.meta, e.bytes, kDims, "'w.vnr'");
  EXPECT_EQ(back.q, r.q);
  EXPECT_FLOAT_EQ((*back.field)[0] , [&] {
    std::vector<float> f(size_t(kDims.count()), 0.0f);
    for (size_t i = 0; i < f.size(); ++i) f[i] = float(r.q[i] * r.step);
    wavelet_inverse(f, kDims, r.wavelet_levels);
    return f[0];
  }());
  ASSERT_TRUE(back.field);
  EXPECT_GT(std::fabs((*back.field)[0]), 0.0f);
  auto error_of = [&](const Json& meta, const std::vector<uint8_t>& bytes) {
    return one_line_error_of([&] { decode_residuals(meta, bytes, kDims, "'w.vnr'"); });
  };
  Json meta = e.meta;
  meta["levels"] = 9;
  EXPECT_HAS(error_of(meta, e.bytes), "wavelet levels");
  meta = e.meta;
  meta["offsets"] = {0.1, 0.2};
  EXPECT_HAS(error_of(meta, e.bytes), "reconstruction offsets");
  meta = e.meta;
  meta["predictor"] = "lorenzo";
  EXPECT_HAS(error_of(meta, e.bytes), "unknown residual coding");
  meta = e.meta;
  meta["crc32"] = meta["crc32"].get<uint64_t>() ^ 1;
  EXPECT_HAS(error_of(meta, e.bytes), "CRC");
  EXPECT_HAS(error_of(e.meta, {}), "'w.vnr'");
}

// A requested bound: the wavelet's coefficients and the outliers they leave keep it at every voxel, the
// smaller of them and the voxel residuals is kept, and both streams survive the block.
TEST(WaveletResiduals, OutliersKeepARequestedBound) {
  const Volume vol = make_volume(kDims, [](float x, float y, float z) {
    return 0.5f + 0.3f * std::sin(6 * x) * std::cos(5 * y) + (std::fabs(z - 0.5f) < 0.05f ? 0.15f : 0.f);
  });
  Model m = model_for(kDims);
  for (double bound : {1e-2, 1e-3}) {
    SCOPED_TRACE(bound);
    std::vector<float> pred(size_t(kDims.count()));
    reference_slices(*m.net, kDims, 0, kDims.z, pred.data());
    const std::optional<Residuals> w = bounded_wavelet_residuals(vol.data.data(), pred.data(), kDims, bound);
    ASSERT_TRUE(w && w->wavelet());
    EXPECT_FALSE(w->outliers.empty());  // a step of 1.5 bound and more leaves some
    EXPECT_LE(residual_error_stats(*w, vol.data.data(), pred.data()).max_abs_error, bound);
    const Residuals back = decode_residuals(w->encoded->meta, w->encoded->bytes, kDims, "'w.vnr'");
    EXPECT_EQ(back.outliers, w->outliers);
    for (size_t i = 0; i < back.field->size(); ++i) ASSERT_EQ(bits((*back.field)[i]), bits((*w->field)[i])) << i;

    const Residuals kept = smallest_residuals(*m.net, vol.data.data(), kDims, bound);
    const Json& sizes = kept.encoded->meta["candidate_bytes"];
    if (kept.wavelet()) EXPECT_LT(kept.encoded->bytes.size(), sizes["voxels"].get<size_t>());
    Model with = model_for(kDims);
    with.residuals = kept;
    EXPECT_LE(max_abs_diff(decode(with), vol.data), bound);

    Json meta = w->encoded->meta;
    meta["outliers"]["crc32"] = meta["outliers"]["crc32"].get<uint64_t>() ^ 1;
    EXPECT_HAS(one_line_error_of([&] { decode_residuals(meta, w->encoded->bytes, kDims, "'w.vnr'"); }), "outliers");
    meta = w->encoded->meta;
    meta["outliers"]["bytes"] = w->encoded->bytes.size() + 1;
    EXPECT_HAS(one_line_error_of([&] { decode_residuals(meta, w->encoded->bytes, kDims, "'w.vnr'"); }), "past its end");
  }
}

// The coefficients' stream (context coder in flagged 8^3 blocks) round-trips exactly on adversarial
// fields: all zeros, all distinct, the extremes of its range (2^30), and a single value in the last
// block; a cut stream is one error. All zeros cost a flag per block, nearly nothing.
TEST(WaveletResiduals, BlockCoderRoundTripsAdversarialFields) {
  const Int3 dims{21, 18, 13};  // partial blocks on every axis
  const size_t n = size_t(dims.count());
  std::vector<std::vector<int32_t>> fields(4, std::vector<int32_t>(n, 0));
  for (size_t i = 0; i < n; ++i) {
    fields[1][i] = int32_t(i) * (i % 2 ? 1 : -1) * 7919;
    fields[2][i] = int32_t(i % 3 == 0 ? kMaxContextMagnitude : i % 3 == 1 ? -kMaxContextMagnitude : 0);
  }
  fields[3][n - 1] = -5;
  for (const auto& q : fields) {
    const std::vector<uint8_t> bytes = context_encode(q.data(), dims, /*wavelet=*/true);
    std::vector<int32_t> back(n, 99);
    context_decode(bytes.data(), bytes.size(), dims, back.data(), "t", true);
    EXPECT_EQ(back, q);
    if (bytes.size() > 16)
      EXPECT_HAS(one_line_error_of([&] { context_decode(bytes.data(), bytes.size() / 2, dims, back.data(), "t", true); }),
                 "corrupted");
  }
  EXPECT_LT(context_encode(fields[0].data(), dims, true).size(), 16u);
  fields[3][0] = INT32_MAX;  // beyond the coder's range: refused, not written undecodable
  EXPECT_HAS(one_line_error_of([&] { context_encode(fields[3].data(), dims, true); }), "out of its range");
}

// Rendering from the brick cache reads a wavelet-residual model's full-resolution bricks with the
// residuals applied: every lookup equals the trilinear lookup of the model's decode.
TEST(WaveletResiduals, TheBrickCacheReadsTheDecodeWithResiduals) {
  const Volume vol = make_volume(kDims, [](float x, float y, float z) { return 0.5f + 0.4f * std::sin(7 * x * y) * z; });
  Model model = model_for(kDims);
  model.residuals = residuals_for_budget(*model.net, vol.data.data(), kDims, 4000);
  ASSERT_TRUE(model.residuals->wavelet());
  Volume decoded;
  decoded.dims = kDims;
  decoded.data.resize(size_t(kDims.count()));
  ModelQuery(model, Device::Cpu).slab(kDims, 0, kDims.z, decoded.data.data());
  NetworkField field(*model.net, model.dims);
  BrickCacheSettings s;
  s.brick = 8;
  s.lod_pixels = 1e-6f;  // level 0 everywhere
  s.decode_seconds = 100;
  std::unique_ptr<CachedField> cache = make_model_cache(model, field, s, std::make_shared<Decoder>(model, Device::Cpu));
  RenderParams p;
  p.cam = make_camera_frame(orbit_camera(box_of(vol), 25, 15, 30), 32, 32);
  p.box = Vec3f{float(kDims.x), float(kDims.y), float(kDims.z)};
  cache->begin_frame(p);
  Pcg32 rng(2);
  std::vector<float> x(2000), y(2000), z(2000), v(2000);
  for (size_t i = 0; i < x.size(); ++i) x[i] = rng.next_float(), y[i] = rng.next_float(), z[i] = rng.next_float();
  cache->query(x.data(), y.data(), z.data(), int64_t(x.size()), v.data());
  cache->decode_pending();
  cache->begin_frame(p);
  cache->query(x.data(), y.data(), z.data(), int64_t(x.size()), v.data());
  EXPECT_EQ(cache->stats().misses, 0);
  for (size_t i = 0; i < x.size(); ++i) ASSERT_EQ(v[i], grid_lookup(view_of(decoded), x[i], y[i], z[i])) << i;
}
