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
#include "vnr/core/error.h"
#include "vnr/core/fileio.h"
#include "vnr/core/json.h"
#include "vnr/volume/volume.h"
#include "vnr/volume/writer.h"
#include "test_support.h"

using namespace vnr;
using namespace vnr::test;
namespace fs = std::filesystem;

namespace {

// Values exercising each type's range (signed types go negative; wide types sit far from zero
// with a narrow spread, which float storage must not wash out).
std::vector<double> test_values(DType t, size_t n) {
  std::vector<double> v(n);
  for (size_t i = 0; i < n; ++i) {
    int64_t k = int64_t(i);
    switch (t) {
      case DType::Int8: v[i] = double(-100 + (k * 7) % 200); break;
      case DType::UInt8: v[i] = double((k * 7) % 256); break;
      case DType::Int16: v[i] = double(-30000 + (k * 311) % 60000); break;
      case DType::UInt16: v[i] = double((k * 977) % 65536); break;
      case DType::Int32: v[i] = double(-2000000000LL + (k * 123456789LL) % 4000000000LL); break;
      case DType::UInt32: v[i] = double(4000000000LL + k * 3); break;
      case DType::Float32: v[i] = double(float(k * 0.37 - 10.0)); break;
      case DType::Float64: v[i] = 1e12 + double(k) * 0.001; break;
    }
  }
  return v;
}

void expect_normalised(const Volume& vol, const std::vector<double>& values, double tol = 1e-6) {
  ASSERT_EQ(vol.data.size(), values.size());
  double lo = *std::min_element(values.begin(), values.end());
  double hi = *std::max_element(values.begin(), values.end());
  EXPECT_DOUBLE_EQ(vol.lo, lo);
  EXPECT_DOUBLE_EQ(vol.hi, hi);
  for (size_t i = 0; i < values.size(); ++i)
    ASSERT_NEAR(vol.data[i], (values[i] - lo) / (hi - lo), tol) << "voxel " << i;
}

RawOptions raw_opts(Int3 dims, const std::string& dtype) {
  RawOptions o;
  o.dims = dims;
  o.dtype = dtype;
  return o;
}

const Int3 kDims{5, 7, 3};  // non-cubic on purpose: catches swapped axes

}  // namespace

// ---------------------------------------------------------------------------------------------
// Raw files and sidecars

TEST(Volume, EveryDtypeBothEndiansWithOffset) {
  TmpDir dir;
  const DType types[] = {DType::Int8,  DType::UInt8,  DType::Int16,   DType::UInt16,
                         DType::Int32, DType::UInt32, DType::Float32, DType::Float64};
  for (DType t : types) {
    for (bool big : {false, true}) {
      SCOPED_TRACE(std::string(dtype_name(t)) + (big ? " big" : " little"));
      auto values = test_values(t, kDims.count());
      const std::string header = "HEADER-13byte";  // 13 bytes: misaligned on purpose
      std::string path = dir / (std::string(dtype_name(t)) + (big ? "_be.bin" : "_le.bin"));
      write_bytes(path, header + encode(t, values, big));
      RawOptions o = raw_opts(kDims, dtype_name(t));
      o.endian = big ? "big" : "little";
      o.offset = header.size();
      VolumeDesc d = describe_volume(path, o);
      EXPECT_EQ(d.dims, kDims);
      EXPECT_EQ(d.dtype, t);
      EXPECT_EQ(d.big_endian, big);
      EXPECT_EQ(d.offset, header.size());
      Volume v = load_volume(d);
      EXPECT_EQ(v.dims, kDims);
      EXPECT_EQ(v.source_dtype, t);
      EXPECT_EQ(v.source_bytes(), kDims.count() * dtype_size(t));
      expect_normalised(v, values);

      // The same file through a sidecar (byte_order, offset and a relative "file").
      Json side = {{"file", fs::path(path).filename().string()},
                   {"dims", {kDims.x, kDims.y, kDims.z}},
                   {"dtype", dtype_name(t)},
                   {"byte_order", big ? "big" : "little"},
                   {"offset", header.size()},
                   {"spacing", {0.5, 1, 2}}};
      std::string json = path + ".json";
      write_bytes(json, side.dump());
      Volume v2 = load_volume(describe_volume(json));
      EXPECT_EQ(v2.data, v.data);
      EXPECT_FLOAT_EQ(v2.spacing.x, 0.5f);
      EXPECT_FLOAT_EQ(v2.spacing.z, 2.f);
    }
  }
}

TEST(Volume, SidecarValueRangeAndFourDimsTimestep) {
  TmpDir dir;
  const Int3 d{4, 3, 2};
  const size_t frame = d.count();
  std::vector<double> values(frame * 3);
  for (size_t i = 0; i < values.size(); ++i) values[i] = double(i * 10);  // timestep t holds 10*(t*24 + i)
  write_bytes(dir / "series.raw", encode(DType::UInt16, values));
  write_bytes(dir / "series.json",
              R"({"file": "series.raw", "dims": [4, 3, 2, 3], "dtype": "uint16", "byte_order": "little",
                  "value_range": [0, 1000]})");

  VolumeDesc d2 = describe_volume(dir / "series.json", [] {
    RawOptions o;
    o.timestep = 2;
    return o;
  }());
  EXPECT_EQ(d2.n_timesteps, 3);
  EXPECT_EQ(d2.timestep, 2);
  EXPECT_EQ(d2.offset, 2 * frame * 2);
  Volume v = load_volume(d2);
  EXPECT_EQ(v.lo, 0);
  EXPECT_EQ(v.hi, 1000);
  for (size_t i = 0; i < frame; ++i) EXPECT_FLOAT_EQ(v.data[i], std::min(1.0, values[2 * frame + i] / 1000.0));

  VolumeDesc d0 = describe_volume(dir / "series.json");
  EXPECT_EQ(d0.timestep, 0);
  EXPECT_EQ(d0.offset, 0u);
  EXPECT_FLOAT_EQ(load_volume(d0).data[5], 50.f / 1000.f);

  // Command-line range overrides the sidecar's.
  RawOptions o;
  o.range_lo = 100;
  o.range_hi = 200;
  Volume vo = load_volume(describe_volume(dir / "series.json", o));
  EXPECT_EQ(vo.lo, 100);
  EXPECT_EQ(vo.hi, 200);
  EXPECT_FLOAT_EQ(vo.data[15], 0.5f);  // 150

  for (int bad : {3, -1}) {
    RawOptions ob;
    ob.timestep = bad;
    std::string m = one_line_error_of([&] { describe_volume(dir / "series.json", ob); });
    EXPECT_HAS(m, "timestep " + std::to_string(bad) + " out of range");
    EXPECT_HAS(m, "3 timesteps");
  }
}

TEST(Volume, PlainRawTimesteps) {
  TmpDir dir;
  std::vector<double> values(kDims.count() * 2);
  std::iota(values.begin(), values.end(), 0.0);
  write_bytes(dir / "two.raw", encode(DType::Float32, values));
  RawOptions o = raw_opts(kDims, "float32");
  o.timestep = 1;
  VolumeDesc d = describe_volume(dir / "two.raw", o);
  EXPECT_EQ(d.n_timesteps, 2);
  Volume v = load_volume(d);
  EXPECT_EQ(v.lo, double(kDims.count()));
  EXPECT_EQ(v.hi, double(2 * kDims.count() - 1));
}

// ---------------------------------------------------------------------------------------------
// instantvnr scene files

TEST(Volume, SceneFractionTrapUnnormalizedKeyAndFileNameArray) {
  TmpDir dir;
  auto values = test_values(DType::UInt16, kDims.count());
  write_bytes(dir / "scene_data_rel.raw", encode(DType::UInt16, values));
  // The first path does not exist; the second is relative to the scene's directory (not the CWD).
  std::string scene = R"({
    // instantvnr files carry comments
    "dataSource": [{ "format": "REGULAR_GRID_RAW_BINARY",
                     "fileName": ["/nonexistent/vnr/data.raw", "scene_data_rel.raw"],
                     "dimensions": {"x": 5, "y": 7, "z": 3},
                     "type": "UNSIGNED_SHORT", "endian": "LITTLE_ENDIAN", "offset": 0 }],
    "view": { "volume": { "scalarMappingRange": {"minimum": 0, "maximum": 0.05} } } })";
  write_bytes(dir / "frac.json", scene);
  VolumeDesc d = describe_volume(dir / "frac.json");
  EXPECT_EQ(d.path, dir / "scene_data_rel.raw");
  EXPECT_EQ(d.dtype, DType::UInt16);
  ASSERT_TRUE(d.range_lo && d.range_hi);
  // Integer data: scalarMappingRange is a fraction of the type's maximum, not raw units.
  EXPECT_DOUBLE_EQ(*d.range_lo, 0.0);
  EXPECT_DOUBLE_EQ(*d.range_hi, 0.05 * 65535);
  Volume v = load_volume(d);
  for (size_t i = 0; i < values.size(); ++i)
    ASSERT_NEAR(v.data[i], std::min(1.0, values[i] / (0.05 * 65535)), 1e-6);

  // The unnormalized key wins and is in raw units.
  std::string both = scene;
  both.replace(both.find("\"scalarMappingRange\""), 0,
               R"("scalarMappingRangeUnnormalized": {"minimum": 100, "maximum": 60000}, )");
  write_bytes(dir / "both.json", both);
  VolumeDesc db = describe_volume(dir / "both.json");
  EXPECT_DOUBLE_EQ(*db.range_lo, 100);
  EXPECT_DOUBLE_EQ(*db.range_hi, 60000);

  // Float data: scalarMappingRange is raw units.
  auto fvalues = test_values(DType::Float32, kDims.count());
  write_bytes(dir / "f.raw", encode(DType::Float32, fvalues, /*big=*/true));
  write_bytes(dir / "float.json", R"({"dataSource": [{"fileName": ")" + dir / "f.raw" + R"(",
      "dimensions": {"x": 5, "y": 7, "z": 3}, "type": "FLOAT", "endian": "BIG_ENDIAN"}],
      "view": {"volume": {"scalarMappingRange": {"minimum": -5, "maximum": 5}}}})");
  Volume vf = load_volume(describe_volume(dir / "float.json"));
  EXPECT_EQ(vf.lo, -5);
  EXPECT_EQ(vf.hi, 5);
  for (size_t i = 0; i < fvalues.size(); ++i)
    ASSERT_NEAR(vf.data[i], std::clamp((fvalues[i] + 5) / 10, 0.0, 1.0), 1e-6);

  // No range key: the data's own min/max.
  write_bytes(dir / "norange.json", R"({"dataSource": [{"fileName": "f.raw", "dimensions": {"x": 5, "y": 7, "z": 3},
      "type": "FLOAT", "endian": "BIG_ENDIAN"}]})");
  expect_normalised(load_volume(describe_volume(dir / "norange.json")), fvalues);

  // None of the listed files exists.
  write_bytes(dir / "missing.json", R"({"dataSource": [{"fileName": ["nope1.raw", "/nope2.raw"],
      "dimensions": {"x": 5, "y": 7, "z": 3}, "type": "FLOAT"}]})");
  std::string m = one_line_error_of([&] { describe_volume(dir / "missing.json"); });
  EXPECT_HAS(m, "not found");
  EXPECT_HAS(m, "nope1.raw");
  EXPECT_HAS(m, "/nope2.raw");
}

TEST(Volume, SceneDivaAndTimeSeries) {
  TmpDir dir;
  auto a = test_values(DType::Int16, kDims.count());
  auto b = a;
  for (auto& x : b) x = -x;
  write_bytes(dir / "a.raw", encode(DType::Int16, a, true));
  write_bytes(dir / "b.raw", encode(DType::Int16, b, true));
  write_bytes(dir / "diva.json", R"({"version": "DIVA", "volume": {"filename": ["a.raw", "b.raw"],
      "dims": {"x": 5, "y": 7, "z": 3}, "type": "SHORT", "bigendian": true, "range": {"x": -30000, "y": 30000}}})");
  RawOptions o;
  o.timestep = 1;
  VolumeDesc d = describe_volume(dir / "diva.json", o);
  EXPECT_EQ(d.n_timesteps, 2);
  EXPECT_EQ(d.path, dir / "b.raw");
  EXPECT_TRUE(d.big_endian);
  Volume v = load_volume(d);
  EXPECT_EQ(v.lo, -30000);
  for (size_t i = 0; i < b.size(); ++i) ASSERT_NEAR(v.data[i], (b[i] + 30000) / 60000, 1e-6);

  // VIDI3D with two dataSource entries = two time steps.
  write_bytes(dir / "series.json", R"({"dataSource": [
      {"fileName": "a.raw", "dimensions": {"x": 5, "y": 7, "z": 3}, "type": "SHORT", "endian": "BIG_ENDIAN"},
      {"fileName": "b.raw", "dimensions": {"x": 5, "y": 7, "z": 3}, "type": "SHORT", "endian": "BIG_ENDIAN"}]})");
  VolumeDesc ds = describe_volume(dir / "series.json", o);
  EXPECT_EQ(ds.path, dir / "b.raw");
  expect_normalised(load_volume(ds), b);
  EXPECT_HAS(one_line_error_of([&] { write_bytes(dir / "bad.json", R"({"version": "VIDI4D", "dataSource": []})");
                            describe_volume(dir / "bad.json"); }),
             "VIDI4D");
}

TEST(Volume, ShippedSceneExamplesParse) {
  // The reference scenes point at machines we do not have: they must fail on the data file, not
  // on parsing (comments, extra keys).
  const std::string ex = std::string(VNR_SHARED_DIR) + "/reference/instantvnr-formats/examples/scene_skull.json";
  if (!file_exists(ex)) GTEST_SKIP() << "../shared/reference absent";
  std::string m = one_line_error_of([&] { describe_volume(ex); });
  EXPECT_HAS(m, "CThead.dat");
  EXPECT_HAS(m, "not found");
}

// ---------------------------------------------------------------------------------------------
// NRRD

namespace {
std::string nrrd_header(const std::string& type, const std::string& sizes, const std::string& extra,
                        int dimension = 3) {
  return "NRRD0004\n# a comment\ntype: " + type + "\ndimension: " + std::to_string(dimension) + "\nsizes: " + sizes +
         "\n" + extra + "key:=value\n";
}
}  // namespace

TEST(Volume, NrrdRawAttachedAndSpacing) {
  TmpDir dir;
  auto values = test_values(DType::Int16, kDims.count());
  std::string hdr = nrrd_header("short", "5 7 3", "endian: big\nencoding: raw\nspacings: 0.5 0.25 2\n") + "\n";
  write_bytes(dir / "a.nrrd", hdr + encode(DType::Int16, values, true));
  VolumeDesc d = describe_volume(dir / "a.nrrd");
  EXPECT_EQ(d.dims, kDims);
  EXPECT_EQ(d.dtype, DType::Int16);
  EXPECT_TRUE(d.big_endian);
  EXPECT_EQ(d.offset, hdr.size());
  EXPECT_FLOAT_EQ(d.spacing.y, 0.25f);
  expect_normalised(load_volume(d), values);

  // "space directions" give the spacing as vector lengths; byte skip; CRLF header lines.
  std::string hdr2 =
      "NRRD0005\r\ntype: uint8\r\ndimension: 3\r\nsizes: 5 7 3\r\nencoding: raw\r\nbyte skip: 4\r\n"
      "space directions: (3, 4,0) (0,2,0) (0,0,1.5)\r\n\r\n";
  auto u8 = test_values(DType::UInt8, kDims.count());
  write_bytes(dir / "b.nrrd", hdr2 + "SKIP" + encode(DType::UInt8, u8));
  VolumeDesc d2 = describe_volume(dir / "b.nrrd");
  EXPECT_FLOAT_EQ(d2.spacing.x, 5.f);
  EXPECT_FLOAT_EQ(d2.spacing.y, 2.f);
  EXPECT_FLOAT_EQ(d2.spacing.z, 1.5f);
  expect_normalised(load_volume(d2), u8);

  // byte skip -1: the data are the last bytes of the file.
  std::string hdr3 = nrrd_header("uint8", "5 7 3", "encoding: raw\nbyte skip: -1\n") + "\n";
  write_bytes(dir / "c.nrrd", hdr3 + "junkjunk" + encode(DType::UInt8, u8));
  expect_normalised(load_volume(describe_volume(dir / "c.nrrd")), u8);
}

TEST(Volume, NrrdGzipAttachedDetachedAndTime) {
  TmpDir dir;
  auto values = test_values(DType::Float32, kDims.count());
  // Attached: header, then a gzip stream (zlib appends a gzip member in "ab" mode).
  std::string hdr = nrrd_header("float", "5 7 3", "endian: little\nencoding: gzip\n") + "\n";
  write_bytes(dir / "g.nrrd", hdr);
  write_gzip(dir / "g.nrrd", encode(DType::Float32, values), "ab");
  VolumeDesc d = describe_volume(dir / "g.nrrd");
  EXPECT_EQ(d.encoding, "gzip");
  EXPECT_EQ(d.gzip_start, hdr.size());
  expect_normalised(load_volume(d), values);

  // Detached header (.nhdr) with gzip data, byte skip counted in decompressed bytes.
  write_bytes(dir / "g.nhdr", nrrd_header("float", "5 7 3", "encoding: gz\nbyte skip: 3\ndata file: g.raw.gz\n"));
  write_gzip(dir / "g.raw.gz", "abc" + encode(DType::Float32, values));
  expect_normalised(load_volume(describe_volume(dir / "g.nhdr")), values);

  // Detached raw.
  write_bytes(dir / "r.nhdr", nrrd_header("float", "5 7 3", "encoding: raw\ndata file: ./r.raw\n"));
  write_bytes(dir / "r.raw", encode(DType::Float32, values));
  expect_normalised(load_volume(describe_volume(dir / "r.nhdr")), values);

  // 4-D, time as the last axis, gzip: timestep 1 is the second frame.
  std::vector<double> two(values);
  for (double v : values) two.push_back(double(float(v * 2 + 100)));  // as stored
  write_bytes(dir / "t.nrrd",
              nrrd_header("float", "5 7 3 2", "encoding: gzip\nkinds: space space space time\n", 4) + "\n");
  write_gzip(dir / "t.nrrd", encode(DType::Float32, two), "ab");
  RawOptions o;
  o.timestep = 1;
  VolumeDesc dt = describe_volume(dir / "t.nrrd", o);
  EXPECT_EQ(dt.n_timesteps, 2);
  std::vector<double> second(two.begin() + long(values.size()), two.end());
  expect_normalised(load_volume(dt), second);

  // 4-D with a degenerate first axis reads as 3-D; a per-voxel vector axis is refused clearly.
  write_bytes(dir / "one.nrrd", nrrd_header("float", "1 5 7 3", "encoding: raw\n", 4) + "\n" +
                                    encode(DType::Float32, values));
  expect_normalised(load_volume(describe_volume(dir / "one.nrrd")), values);
  write_bytes(dir / "vec.nrrd", nrrd_header("float", "3 5 7 3", "encoding: raw\nkinds: 3-vector space space space\n", 4) +
                                    "\n" + encode(DType::Float32, two));
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "vec.nrrd"); }), "not supported");

  // Decompressed size checks: too short and too long, with both byte counts.
  std::string data = encode(DType::Float32, values);
  write_gzip(dir / "short.gz", data.substr(0, data.size() - 8));
  write_bytes(dir / "short.nhdr", nrrd_header("float", "5 7 3", "encoding: gzip\ndata file: short.gz\n"));
  std::string m = one_line_error_of([&] { load_volume(describe_volume(dir / "short.nhdr")); });
  EXPECT_HAS(m, "decompresses to " + std::to_string(data.size() - 8) + " bytes");
  EXPECT_HAS(m, "expected " + std::to_string(data.size()));
  write_gzip(dir / "long.gz", data + "extra");
  write_bytes(dir / "long.nhdr", nrrd_header("float", "5 7 3", "encoding: gzip\ndata file: long.gz\n"));
  m = one_line_error_of([&] { load_volume(describe_volume(dir / "long.nhdr")); });
  EXPECT_HAS(m, "decompresses to " + std::to_string(data.size() + 5) + " bytes");
  EXPECT_HAS(m, "expected " + std::to_string(data.size()));

  // Labelled gzip but not compressed.
  write_bytes(dir / "fake.nrrd", hdr + data);
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "fake.nrrd"); }), "not a gzip stream");
}

TEST(Volume, NrrdMalformedHeaders) {
  TmpDir dir;
  write_bytes(dir / "nomagic.nrrd", "NRRX0004\ntype: float\n\n");
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "nomagic.nrrd"); }), "not a NRRD file");
  write_bytes(dir / "nosizes.nrrd", "NRRD0004\ntype: float\ndimension: 3\nencoding: raw\n\n");
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "nosizes.nrrd"); }), "missing 'sizes'");
  write_bytes(dir / "mismatch.nrrd", "NRRD0004\ntype: float\ndimension: 3\nsizes: 4 4\nencoding: raw\n\n");
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "mismatch.nrrd"); }), "dimension 3 but 2 sizes");
  write_bytes(dir / "garbage.nrrd", "NRRD0004\ntype float\n\n");
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "garbage.nrrd"); }), "malformed NRRD header line 2");
  write_bytes(dir / "enc.nrrd", "NRRD0004\ntype: float\ndimension: 3\nsizes: 1 1 1\nencoding: bzip2\n\n");
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "enc.nrrd"); }), "encoding 'bzip2' is not supported");
  write_bytes(dir / "type.nrrd", "NRRD0004\ntype: complex\ndimension: 3\nsizes: 1 1 1\nencoding: raw\n\n");
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "type.nrrd"); }), "unknown data type 'complex'");
  write_bytes(dir / "nodata.nhdr", nrrd_header("float", "5 7 3", "encoding: raw\ndata file: gone.raw\n"));
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "nodata.nhdr"); }), "gone.raw");
  write_bytes(dir / "short.nrrd", nrrd_header("uint8", "5 7 3", "encoding: raw\n") + "\n" + std::string(100, 'x'));
  EXPECT_HAS(one_line_error_of([&] { describe_volume(dir / "short.nrrd"); }), "expected");
}

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

// ---------------------------------------------------------------------------------------------
// Real data (../shared/data)

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

