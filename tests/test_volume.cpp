// Volume readers: raw files of every dtype and byte order, JSON sidecars, instantvnr scenes and NRRD.
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
