// Volume writers (raw + sidecar, NRRD, slab by slab) and the synthetic volumes.
#include <gtest/gtest.h>
#include <hwy/targets.h>
#include "vnr/core/rng.h"
#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <numeric>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/json.h"
#include "vnr/volume/volume.h"
#include "vnr/volume_writer.h"
#include "test_support.h"
#include "volume_support.h"

using namespace vnr;
using namespace vnr::test;
namespace fs = std::filesystem;

// ---------------------------------------------------------------------------------------------
// Writer

TEST(Writer, RawRoundTripAndSidecar) {
  TmpDir dir;
  std::vector<float> values(kDims.count());
  for (size_t i = 0; i < values.size(); ++i) values[i] = float(i) * 600.4f - 100.f;  // clamps below 0
  {
    VolumeWriter w(dir / "out.raw", kDims, DType::UInt16, Vec3f{0.88f, 1.f, 2.5f});
    EXPECT_EQ(w.sidecar_path(), dir / "out.json");
    w.write_slices(values.data(), 1);
    w.write_slices(values.data() + 35, 2);
    w.commit();
  }
  Json side = parse_json_file(dir / "out.json");
  EXPECT_EQ(side["file"], "out.raw");
  EXPECT_EQ(side["dims"], Json({5, 7, 3}));
  EXPECT_EQ(side["dtype"], "uint16");
  EXPECT_EQ(side["byte_order"], "little");
  EXPECT_EQ(side["spacing"][2].get<double>(), 2.5);
  EXPECT_HAS(read_file(dir / "out.json"), "[0.88, 1, 2.5]");  // floats printed as floats
  // Stored = round-to-nearest, clamped to the type; the range is that of the stored values.
  std::vector<double> stored(values.size());
  for (size_t i = 0; i < values.size(); ++i) stored[i] = std::clamp(std::nearbyint(double(values[i])), 0.0, 65535.0);
  EXPECT_EQ(side["value_range"][0].get<double>(), 0);
  EXPECT_EQ(side["value_range"][1].get<double>(), *std::max_element(stored.begin(), stored.end()));
  Volume v = load_volume(describe_volume(dir / "out.json"));
  EXPECT_EQ(v.source_dtype, DType::UInt16);
  EXPECT_FLOAT_EQ(v.spacing.z, 2.5f);
  expect_normalised(v, stored);
  // Raw bytes are little-endian uint16.
  EXPECT_EQ(read_file(dir / "out.raw"), encode(DType::UInt16, stored));
}

TEST(Writer, NrrdRoundTrip) {
  TmpDir dir;
  std::vector<float> values(kDims.count());
  for (size_t i = 0; i < values.size(); ++i) values[i] = std::sin(float(i)) * 3;
  VolumeWriter w(dir / "out.nrrd", kDims, DType::Float32, Vec3f{1.f, 0.5f, 0.25f});
  EXPECT_EQ(w.sidecar_path(), "");
  w.write_slices(values.data(), 3);
  w.commit();
  std::string text = read_file(dir / "out.nrrd");
  for (const char* key : {"type: float\n", "dimension: 3\n", "sizes: 5 7 3\n", "endian: little\n", "encoding: raw\n",
                          "spacings: 1 0.5 0.25\n"})
    EXPECT_HAS(text, key);
  VolumeDesc d = describe_volume(dir / "out.nrrd");
  EXPECT_FLOAT_EQ(d.spacing.y, 0.5f);
  EXPECT_FALSE(fs::exists(dir / "out.json"));
  expect_normalised(load_volume(d), std::vector<double>(values.begin(), values.end()));
}

TEST(Writer, SlabsEqualOneWriteAndErrors) {
  TmpDir dir;
  const Int3 d{6, 4, 9};
  std::vector<float> values(d.count());
  for (size_t i = 0; i < values.size(); ++i) values[i] = float(i % 17) * 0.25f;
  {
    VolumeWriter a(dir / "a.raw", d, DType::Float32);
    a.write_slices(values.data(), d.z);
    a.commit();
    VolumeWriter b(dir / "b.raw", d, DType::Float32);
    for (int64_t z = 0; z < d.z;) {
      int64_t n = std::min<int64_t>(z % 2 ? 1 : 3, d.z - z);  // uneven slabs
      b.write_slices(values.data() + z * d.x * d.y, n);
      z += n;
    }
    b.commit();
  }
  EXPECT_EQ(read_file(dir / "a.raw"), read_file(dir / "b.raw"));
  Json ja = parse_json_file(dir / "a.json"), jb = parse_json_file(dir / "b.json");
  EXPECT_EQ(ja["value_range"], jb["value_range"]);
  EXPECT_EQ(ja["value_range"], Json({0, 4}));

  {
    VolumeWriter c(dir / "c.raw", d, DType::Float32);
    c.write_slices(values.data(), 2);
    EXPECT_HAS(one_line_error_of([&] { c.commit(); }), "2 of 9 z-slices");
    EXPECT_HAS(one_line_error_of([&] { c.write_slices(values.data(), 8); }), "exceed dims.z");
  }
  // Nothing is left behind by an uncommitted writer, not even a temporary.
  for (auto& e : fs::directory_iterator(dir.str())) EXPECT_EQ(e.path().filename().string().find("c."), std::string::npos) << e.path();
}

// ---------------------------------------------------------------------------------------------
// Synthetic volumes

namespace {
double ml_closed_form(double x, double y, double z) {  // Marschner & Lobb 1994, alpha 0.25, f_M 6
  const double pi = std::numbers::pi;
  double r = std::hypot(x, y);
  return (1 - std::sin(pi * z / 2) + 0.25 * (1 + std::cos(2 * pi * 6 * std::cos(pi * r / 2)))) / 2.5;
}
}  // namespace

TEST(Synth, MarschnerLobbClosedForm) {
  // u = 0.5 is the origin: r = 0, rho_r = cos(12 pi) = 1 -> (1 + 0.5)/2.5 = 0.6.
  EXPECT_NEAR(synth_value("marschner-lobb", 0.5f, 0.5f, 0.5f), 0.6, 1e-6);
  // z = 1 (u = 1), x = y = 0: (1 - 1 + 0.5)/2.5 = 0.2.
  EXPECT_NEAR(synth_value("marschner-lobb", 0.5f, 0.5f, 1.0f), 0.2, 1e-6);
  const float pts[][3] = {{0.1f, 0.2f, 0.3f}, {0.9f, 0.25f, 0.75f}, {0.0f, 1.0f, 0.5f}, {0.33f, 0.66f, 0.01f}};
  for (auto& p : pts)
    EXPECT_NEAR(synth_value("marschner-lobb", p[0], p[1], p[2]),
                ml_closed_form(2.0 * p[0] - 1, 2.0 * p[1] - 1, 2.0 * p[2] - 1), 1e-6);
  EXPECT_HAS(one_line_error_of([] { synth_value("perlin", 0, 0, 0); }), "unknown synthetic volume 'perlin'");
}

TEST(Synth, VolumesMatchPointValuesAndSidecarRange) {
  TmpDir dir;
  const Int3 d{9, 6, 5};
  for (const char* kind : {"marschner-lobb", "noise"}) {
    SCOPED_TRACE(kind);
    std::string json = dir / (std::string(kind) + ".json");
    synth_volume(kind, d, json, 7);
    Json side = parse_json_file(json);
    EXPECT_EQ(side["dtype"], "float32");
    EXPECT_EQ(side["file"], std::string(kind) + ".raw");
    // Raw floats: voxel centres equal synth_value; the sidecar range is their exact min/max.
    std::string bytes = read_file(dir / (std::string(kind) + ".raw"));
    ASSERT_EQ(bytes.size(), d.count() * 4);
    std::vector<float> raw(d.count());
    std::memcpy(raw.data(), bytes.data(), bytes.size());
    for (int64_t z = 0; z < d.z; ++z)
      for (int64_t y = 0; y < d.y; ++y)
        for (int64_t x = 0; x < d.x; ++x) {
          float u[3] = {float((x + 0.5) / d.x), float((y + 0.5) / d.y), float((z + 0.5) / d.z)};
          ASSERT_EQ(raw[size_t(x + d.x * (y + d.y * z))], synth_value(kind, u[0], u[1], u[2], 7));
        }
    auto [mn, mx] = std::minmax_element(raw.begin(), raw.end());
    EXPECT_EQ(side["value_range"][0].get<double>(), double(*mn));
    EXPECT_EQ(side["value_range"][1].get<double>(), double(*mx));
    EXPECT_GE(*mn, 0.f);
    EXPECT_LE(*mx, 1.f);
    Volume v = load_volume(describe_volume(json));
    EXPECT_EQ(v.lo, double(*mn));
    EXPECT_EQ(v.hi, double(*mx));
  }
}

TEST(Synth, NoiseIsDeterministicSeededAndMultiScale) {
  double sum = 0, sum2 = 0;
  int n = 0, differ = 0;
  for (int i = 0; i < 2000; ++i) {
    float u[3] = {float((i * 0.6180339) - std::floor(i * 0.6180339)), float((i * 0.4142135) - std::floor(i * 0.4142135)),
                  float((i * 0.7320508) - std::floor(i * 0.7320508))};
    float a = synth_value("noise", u[0], u[1], u[2], 1);
    EXPECT_EQ(a, synth_value("noise", u[0], u[1], u[2], 1));
    differ += a != synth_value("noise", u[0], u[1], u[2], 2);
    ASSERT_GE(a, 0.f);
    ASSERT_LE(a, 1.f);
    sum += a;
    sum2 += double(a) * a;
    ++n;
  }
  EXPECT_GT(differ, 1990);
  double mean = sum / n, sd = std::sqrt(sum2 / n - mean * mean);
  EXPECT_NEAR(mean, 0.5, 0.1);
  EXPECT_GT(sd, 0.05);  // not flat
  // Fine octaves: neighbouring points 1/512 apart still differ.
  EXPECT_NE(synth_value("noise", 0.5f, 0.5f, 0.5f), synth_value("noise", 0.5f + 1.f / 512, 0.5f, 0.5f));
}

TEST(Synth, RejectsBadOutputs) {
  TmpDir dir;
  EXPECT_HAS(one_line_error_of([&] { synth_volume("noise", {4, 4, 4}, dir / "x.raw"); }), ".json sidecar path");
  EXPECT_HAS(one_line_error_of([&] { synth_volume("noise", {0, 4, 4}, dir / "x.json"); }), "invalid dims");
}
