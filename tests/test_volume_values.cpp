// Volume errors, value policies and lookup: bad inputs give one clear error, non-finite and constant
// data, grid lookup (scalar and batched) and the shared real data set.
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
// Validation

TEST(Volume, SizeMismatchNamesExpectedAndActualBytes) {
  TmpDir dir;
  write_bytes(dir / "a.raw", std::string(1000, '\0'));
  std::string m = one_line_error_of([&] { describe_volume(dir / "a.raw", raw_opts({16, 8, 8}, "uint8")); });
  EXPECT_HAS(m, "a.raw' has 1000 bytes, expected 1024 (16x8x8 uint8 + offset 0)");
  write_bytes(dir / "b.raw", std::string(2050, '\0'));
  RawOptions o = raw_opts({16, 8, 8}, "uint16");
  m = one_line_error_of([&] { describe_volume(dir / "b.raw", o); });
  EXPECT_HAS(m, "has 2050 bytes, expected 2048 (16x8x8 uint16 + offset 0)");
  o.offset = 4;
  m = one_line_error_of([&] { describe_volume(dir / "b.raw", o); });
  EXPECT_HAS(m, "has 2050 bytes, expected 2052 (16x8x8 uint16 + offset 4)");
  o.offset = 2;
  EXPECT_NO_THROW(describe_volume(dir / "b.raw", o));

  // Sidecar with 4-D dims: the whole series must be there.
  write_bytes(dir / "s.json", R"({"file": "b.raw", "dims": [16, 8, 8, 2], "dtype": "uint8"})");
  m = one_line_error_of([&] { describe_volume(dir / "s.json"); });
  EXPECT_HAS(m, "has 2050 bytes, expected 2048 (16x8x8x2 uint8 + offset 0)");
}

TEST(Volume, MissingFilesAndMalformedDescriptors) {
  TmpDir dir;
  std::string m = one_line_error_of([&] { describe_volume(dir / "nope.raw", raw_opts({1, 1, 1}, "uint8")); });
  EXPECT_HAS(m, "nope.raw");
  EXPECT_HAS(m, "No such file");
  write_bytes(dir / "s.json", R"({"file": "gone.raw", "dims": [2, 2, 2], "dtype": "uint8"})");
  m = one_line_error_of([&] { describe_volume(dir / "s.json"); });
  EXPECT_HAS(m, dir / "gone.raw");
  EXPECT_HAS(m, "s.json");
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir.str()); }), "is a directory");

  write_bytes(dir / "bad.json", R"({"file": "x.raw", "dims": [2, 2, 2], )");
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "bad.json"); }), "invalid JSON");
  write_bytes(dir / "neither.json", R"({"hello": 1})");
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "neither.json"); }), "neither a vnr sidecar");
  write_bytes(dir / "dims.json", R"({"file": "x.raw", "dims": [2, 2], "dtype": "uint8"})");
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "dims.json"); }), "3 or 4 integers");
  write_bytes(dir / "nodtype.json", R"({"file": "x.raw", "dims": [2, 2, 2]})");
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "nodtype.json"); }), "missing \"dtype\"");
  write_bytes(dir / "frac.json", R"({"file": "x.raw", "dims": [2, 2.5, 2], "dtype": "uint8"})");
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "frac.json"); }), "must be an integer");

  write_bytes(dir / "x.raw", std::string(8, '\0'));
  m = one_line_error_of([&] { describe_volume(dir / "x.raw"); });
  EXPECT_HAS(m, "--dims X,Y,Z and --dtype T are required for raw file '" + dir / "x.raw" + "'");
  RawOptions only_dims;
  only_dims.dims = Int3{2, 2, 2};
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "x.raw", only_dims); }), "are required for raw file");
  m = one_line_error_of([&] { describe_volume(dir / "x.raw", raw_opts({2, 2, 2}, "complex64")); });
  EXPECT_HAS(m, "unknown data type 'complex64'");
  EXPECT_HAS(m, "allowed: int8, uint8");
  RawOptions e = raw_opts({2, 2, 2}, "uint8");
  e.endian = "middle";
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "x.raw", e); }), "unknown --endian 'middle'");
  RawOptions r = raw_opts({2, 2, 2}, "uint8");
  r.range_lo = 5;
  r.range_hi = 1;
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "x.raw", r); }), "lo > hi");
}

TEST(Volume, BadDims) {
  TmpDir dir;
  write_bytes(dir / "x.raw", std::string(8, '\0'));
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "x.raw", raw_opts({0, 2, 2}, "uint8")); }),
             "dims 0x2x2 must all be positive");
  write_bytes(dir / "neg.json", R"({"file": "x.raw", "dims": [2, -2, 2], "dtype": "uint8"})");
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "neg.json"); }), "dims 2x-2x2 must all be positive");
  const int64_t big = int64_t(1) << 32;
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "x.raw", raw_opts({big, big, big}, "uint8")); }),
             "overflow");
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "x.raw", raw_opts({1 << 20, 1 << 20, 2}, "uint8")); }),
             "exceed the limit of 2^40");
  write_bytes(dir / "huge.json", R"({"file": "x.raw", "dims": [2, 2, 18446744073709551615], "dtype": "uint8"})");
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "huge.json"); }), "too large");
}

// ---------------------------------------------------------------------------------------------
// Non-finite values and degenerate ranges

TEST(Volume, NonFinitePolicies) {
  TmpDir dir;
  std::vector<double> values(kDims.count());
  for (size_t i = 0; i < values.size(); ++i) values[i] = double(i);  // 0..104
  const double inf = std::numeric_limits<double>::infinity();
  auto idx = [](int x, int y, int z) { return size_t(x + 5 * (y + 7 * z)); };
  values[idx(1, 2, 0)] = std::nan("");
  values[idx(4, 6, 2)] = inf;  // the maximum voxel
  values[idx(0, 0, 1)] = -inf;
  write_bytes(dir / "nan.raw", encode(DType::Float64, values));
  VolumeDesc d = describe_volume(dir / "nan.raw", raw_opts(kDims, "float64"));

  std::string m = one_line_error_of([&] { load_volume(d); });
  EXPECT_HAS(m, "nan.raw' contains 3 NaN/Inf values (first at voxel (1,2,0)); use --nan zero|clamp");

  // Range over finite values only: 0 .. 103.
  LoadOptions zero{NonFinitePolicy::Zero};
  Volume vz = load_volume(d, zero);
  EXPECT_EQ(vz.lo, 0);
  EXPECT_EQ(vz.hi, 103);
  EXPECT_EQ(vz.data[idx(1, 2, 0)], 0.f);
  EXPECT_EQ(vz.data[idx(4, 6, 2)], 0.f);
  EXPECT_EQ(vz.data[idx(0, 0, 1)], 0.f);
  EXPECT_FLOAT_EQ(vz.data[50], 50.f / 103.f);

  LoadOptions clamp{NonFinitePolicy::Clamp};
  Volume vc = load_volume(d, clamp);
  EXPECT_EQ(vc.data[idx(1, 2, 0)], 0.f);
  EXPECT_EQ(vc.data[idx(4, 6, 2)], 1.f);
  EXPECT_EQ(vc.data[idx(0, 0, 1)], 0.f);
  EXPECT_EQ(vc.data[103], 1.f);

  // Integers cannot hold NaN: the policy is irrelevant and nothing is reported.
  write_bytes(dir / "int.raw", encode(DType::Int32, std::vector<double>(kDims.count(), 7)));
  EXPECT_NO_THROW(load_volume(describe_volume(dir / "int.raw", raw_opts(kDims, "int32"))));
}

TEST(Volume, ConstantVolumeMapsToZero) {
  TmpDir dir;
  write_bytes(dir / "c.raw", encode(DType::Float32, std::vector<double>(kDims.count(), 3.25)));
  Volume v = load_volume(describe_volume(dir / "c.raw", raw_opts(kDims, "float32")));
  EXPECT_EQ(v.lo, 3.25);
  EXPECT_EQ(v.hi, 3.25);
  for (float x : v.data) ASSERT_EQ(x, 0.f);
  // An explicit empty range behaves the same (no division by zero).
  RawOptions o = raw_opts(kDims, "float32");
  o.range_lo = o.range_hi = 1.0;
  Volume v2 = load_volume(describe_volume(dir / "c.raw", o));
  for (float x : v2.data) ASSERT_EQ(x, 0.f);
  // A one-sided explicit range beyond the data clamps, without inverting the mapping.
  RawOptions lo_only = raw_opts(kDims, "float32");
  lo_only.range_lo = 10;
  Volume v3 = load_volume(describe_volume(dir / "c.raw", lo_only));
  for (float x : v3.data) ASSERT_EQ(x, 0.f);
}

// ---------------------------------------------------------------------------------------------
// Lookup (docs/semantics.md B.2)

TEST(Volume, GridLookupReproducesLinearRamp) {
  Volume v;
  v.dims = kDims;
  v.data.resize(kDims.count());
  // f(i,j,k) = (i + 2j + 3k) / 28: linear in the voxel index, so trilinear lookup is exact.
  auto f = [](double i, double j, double k) { return (i + 2 * j + 3 * k) / 28.0; };
  for (int z = 0; z < 3; ++z)
    for (int y = 0; y < 7; ++y)
      for (int x = 0; x < 5; ++x) v.data[size_t(x + 5 * (y + 7 * z))] = float(f(x, y, z));
  GridView g = view_of(v);
  // Voxel centres return voxel values.
  for (int z = 0; z < 3; ++z)
    for (int y = 0; y < 7; ++y)
      for (int x = 0; x < 5; ++x)
        ASSERT_NEAR(grid_lookup(g, (x + 0.5f) / 5, (y + 0.5f) / 7, (z + 0.5f) / 3), f(x, y, z), 1e-6);
  // Inside: p = u*N - 0.5 in voxel units.
  const float pts[][3] = {{0.31f, 0.52f, 0.5f}, {0.7f, 0.2f, 0.4f}, {0.15f, 0.9f, 0.6f}, {0.5f, 0.5f, 0.5f}};
  for (auto& p : pts)
    EXPECT_NEAR(grid_lookup(g, p[0], p[1], p[2]), f(p[0] * 5 - 0.5, p[1] * 7 - 0.5, p[2] * 3 - 0.5), 1e-6);
  // Borders clamp to the edge voxels (within half a voxel of the boundary the value is constant).
  EXPECT_NEAR(grid_lookup(g, 0.f, 0.f, 0.f), f(0, 0, 0), 1e-7);
  EXPECT_NEAR(grid_lookup(g, 0.05f, 0.5f / 7, 0.5f / 3), f(0, 0, 0), 1e-7);
  EXPECT_NEAR(grid_lookup(g, 0.9999f, 0.9999f, 0.9999f), f(4, 6, 2), 1e-6);
  EXPECT_NEAR(grid_lookup(g, 1.0f, 0.5f, 0.0f), f(4, 3, 0), 1e-6);
  // Single-voxel axes.
  Volume one;
  one.dims = {1, 1, 1};
  one.data = {0.75f};
  EXPECT_EQ(grid_lookup(view_of(one), 0.3f, 0.9f, 0.0f), 0.75f);
}

// ---------------------------------------------------------------------------------------------
// Real data (the project's shared data set beside the repository; skipped without it)

TEST(RealData, BonsaiLoads) {
  const std::string path = std::string(VNR_SHARED_DIR) + "/data/bonsai.json";
  if (!file_exists(path)) GTEST_SKIP() << "../shared/data absent";
  VolumeDesc d = describe_volume(path);
  EXPECT_EQ(d.dims, (Int3{256, 256, 256}));
  EXPECT_EQ(d.dtype, DType::UInt8);
  Volume v = load_volume(d);
  EXPECT_EQ(v.lo, 0);
  EXPECT_EQ(v.hi, 255);
  double sum = 0;
  for (float x : v.data) sum += double(x);
  EXPECT_NEAR(sum / double(v.data.size()) * 255.0, 13.711380004882812, 1e-6);
}

TEST(Lookup, BatchIsBitIdenticalToPointLookup) {
  // Non-cubic, odd sizes, 1 and 2 voxels wide in x (the SIMD lookup loads x-neighbours as pairs from
  // 2 voxels up), 1 voxel in y and z; points inside, on the border and outside [0,1] (clamped), NaN;
  // values of both signs.
  for (const vnr::Int3 dims : {vnr::Int3{7, 5, 3}, vnr::Int3{2, 3, 4}, vnr::Int3{1, 4, 2}, vnr::Int3{19, 1, 1}}) {
    const int nx = int(dims.x), ny = int(dims.y), nz = int(dims.z);
    std::vector<float> data(size_t(nx) * ny * nz);
    for (size_t i = 0; i < data.size(); ++i) data[i] = float((i * 7919) % 101) / 100.0f - (i % 5 == 0 ? 0.3f : 0.f);
    vnr::GridView g{data.data(), nx, ny, nz};
    std::vector<float> x, y, z;
    vnr::Pcg32 rng(5);
    for (int i = 0; i < 1000; ++i) {
      x.push_back(i % 13 == 0 ? 1.0f : rng.next_float() * 1.2f - 0.1f);
      y.push_back(rng.next_float());
      z.push_back(i % 17 == 0 ? 1.0f : rng.next_float());
    }
    x.push_back(std::nanf(""));  // NaN coordinates clamp to 0, as in grid_lookup
    y.push_back(0.5f);
    z.push_back(std::nanf(""));
    std::vector<float> out(x.size());
    for (int64_t t : hwy::SupportedAndGeneratedTargets()) {  // every SIMD target this machine has
      hwy::SetSupportedTargetsForTest(t);
      vnr::grid_lookup_batch(g, x.data(), y.data(), z.data(), int64_t(x.size()), out.data());
      for (size_t i = 0; i < x.size(); ++i) {
        const float want = vnr::grid_lookup(g, x[i], y[i], z[i]);
        ASSERT_EQ(out[i], want) << hwy::TargetName(t) << " " << i << " nx " << nx;
      }
    }
    hwy::SetSupportedTargetsForTest(0);
  }
}
