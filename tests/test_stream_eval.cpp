// Evaluating volumes that need not fit in memory (volume/stream.h, volume/raw_access.h,
// train/model_io.h): the streamed value range and slabs and the voxels read at random must
// reproduce load_volume exactly, streamed evaluation must reproduce evaluate(), and the sampled
// estimate must bracket the full PSNR.
#include <gtest/gtest.h>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>
#include "vnr/error.h"
#include "vnr/metrics.h"
#include "vnr/core/rng.h"
#include "vnr/model_config.h"
#include "vnr/nn/network.h"
#include "vnr/train/model_io.h"
#include "vnr/volume/raw_access.h"
#include "vnr/volume/stream.h"
#include "vnr/volume/volume.h"
#include "vnr/volume_writer.h"
#include "test_support.h"

using namespace vnr;
using namespace vnr::test;
namespace fs = std::filesystem;

namespace {

// A raw volume of one dtype and byte order: values spread over most of the type's range, or for
// floats around an offset far from zero (where the pivot in load_volume matters for the rounding).
struct Case {
  DType dtype;
  bool big;
  double base, spread;
};

const Case kCases[] = {
    {DType::UInt8, false, 0, 255},           {DType::Int8, true, -128, 255},
    {DType::Int16, true, -30000, 60000},     {DType::UInt16, false, 0, 65535},
    {DType::Int32, false, -2.0e9, 4.0e9},    {DType::UInt32, true, 1000, 4.0e9},
    {DType::Float32, false, 1000.0, 0.125},  {DType::Float32, true, -3.0, 7.0},
    {DType::Float64, true, 1.0e12, 3.0e-3},  {DType::Float64, false, -1e-3, 2e-3},
};

std::vector<double> random_values(const Case& c, size_t n, uint64_t seed) {
  Pcg32 rng(seed);
  std::vector<double> v(n);
  for (double& x : v) {
    double u = double(rng.next_uint()) / 4294967296.0;
    x = c.base + u * c.spread;
    if (dtype_is_integer(c.dtype)) x = std::floor(x);
  }
  return v;
}

VolumeDesc write_raw(const std::string& path, const Case& c, Int3 dims, const std::vector<double>& values,
                     RawOptions o = {}) {
  write_bytes(path, encode(c.dtype, values, c.big));
  o.dims = dims;
  o.dtype = dtype_name(c.dtype);
  o.endian = c.big ? "big" : "little";
  return describe_volume(path, o);
}

std::vector<float> concatenated_slabs(const VolumeDesc& d, double lo, double hi, const LoadOptions& opts,
                                      int64_t slab_voxels) {
  std::vector<float> all;
  int64_t next_z = 0;
  for_each_slab(d, lo, hi, opts, slab_voxels, [&](int64_t z0, int64_t nz, const float* v) {
    EXPECT_EQ(z0, next_z);
    EXPECT_LE(nz * d.dims.x * d.dims.y, std::max<int64_t>(slab_voxels, d.dims.x * d.dims.y));
    next_z = z0 + nz;
    all.insert(all.end(), v, v + nz * d.dims.x * d.dims.y);
  });
  EXPECT_EQ(next_z, d.dims.z);
  return all;
}

void expect_bitwise_equal(const std::vector<float>& a, const Volume& v, const std::string& what) {
  ASSERT_EQ(a.size(), v.data.size()) << what;
  EXPECT_EQ(std::memcmp(a.data(), v.data.data(), a.size() * sizeof(float)), 0) << what;
}

std::string nrrd_header(const std::string& type, const std::string& sizes, const std::string& extra) {
  return "NRRD0004\ntype: " + type + "\ndimension: 3\nsizes: " + sizes + "\n" + extra + "\n";
}

// A network whose output varies over the volume: the small preset with its grid filled from
// U[-1, 1] (the tcnn initialisation U[-1e-4, 1e-4] gives an almost constant field).
std::unique_ptr<Network> varied_network(uint32_t seed) {
  auto net = std::make_unique<Network>(preset_config("small"));
  net->init_params(seed);
  Pcg32 rng(seed + 17);
  net->edit_params([&](float* p, size_t) {
    float* table = p + net->mlp().n_params;
    for (uint64_t i = 0; i < net->grid_params(); ++i) table[i] = 2 * rng.next_float() - 1;
  });
  return net;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Value range and slabs: exactly load_volume's

TEST(StreamVolume, ScanValueRangeEqualsLoadVolumeOnEveryDtype) {
  TmpDir dir;
  const Int3 dims{13, 11, 9};
  int k = 0;
  for (const Case& c : kCases) {
    SCOPED_TRACE(std::string(dtype_name(c.dtype)) + (c.big ? " big" : " little"));
    auto values = random_values(c, size_t(dims.count()), uint64_t(k));
    VolumeDesc d = write_raw(dir / (std::to_string(k++) + ".raw"), c, dims, values);
    Volume v = load_volume(d);
    double fractions = 0;
    ValueRange r = scan_value_range(d, {}, [&](double f) { fractions = f; });
    EXPECT_EQ(r.lo, v.lo);
    EXPECT_EQ(r.hi, v.hi);
    EXPECT_EQ(fractions, 1.0);
    if (dtype_is_integer(c.dtype)) {
      EXPECT_EQ(r.lo, *std::min_element(values.begin(), values.end()));
    }
  }
}

TEST(StreamVolume, ScanValueRangeHonoursExplicitEnds) {
  TmpDir dir;
  const Int3 dims{6, 5, 4};
  const Case c{DType::Int16, false, -500, 1000};
  auto values = random_values(c, size_t(dims.count()), 3);
  const std::string path = dir / "v.raw";
  for (auto [lo, hi] : std::vector<std::pair<std::optional<double>, std::optional<double>>>{
           {-1000.0, 2000.0},
           {-1000.0, std::nullopt},
           {std::nullopt, 0.0},
           {std::nullopt, -900.0},
           {800.0, std::nullopt}}) {
    RawOptions o;
    o.range_lo = lo;
    o.range_hi = hi;
    VolumeDesc d = write_raw(path, c, dims, values, o);
    Volume v = load_volume(d);
    ValueRange r = scan_value_range(d);
    EXPECT_EQ(r.lo, v.lo);
    EXPECT_EQ(r.hi, v.hi);
    expect_bitwise_equal(concatenated_slabs(d, r.lo, r.hi, {}, 2 * 30), v, "explicit ends");
  }
  // Both ends given: nothing is read, so even a file that vanished gives the range.
  RawOptions o;
  o.range_lo = 1.5;
  o.range_hi = 2.5;
  VolumeDesc d = write_raw(path, c, dims, values, o);
  fs::remove(path);
  ValueRange r = scan_value_range(d);
  EXPECT_EQ(r.lo, 1.5);
  EXPECT_EQ(r.hi, 2.5);
}

TEST(StreamVolume, SlabsConcatenateToLoadVolumeBitForBit) {
  TmpDir dir;
  const Int3 dims{13, 11, 9};
  int k = 0;
  for (const Case& c : kCases) {
    SCOPED_TRACE(std::string(dtype_name(c.dtype)) + (c.big ? " big" : " little"));
    auto values = random_values(c, size_t(dims.count()), uint64_t(100 + k));
    VolumeDesc d = write_raw(dir / (std::to_string(k++) + ".raw"), c, dims, values);
    Volume v = load_volume(d);
    ValueRange r = scan_value_range(d);
    // One slice, a few slices (not dividing 9), anything below one slice, the whole volume.
    for (int64_t slab : {int64_t(143), int64_t(4 * 143), int64_t(5), int64_t(1) << 30})
      expect_bitwise_equal(concatenated_slabs(d, r.lo, r.hi, {}, slab), v, "slab " + std::to_string(slab));
  }
}

TEST(StreamVolume, GzipNrrdStreamsLikeLoadVolume) {
  TmpDir dir;
  const Int3 dims{7, 6, 5};
  const Case c{DType::Float32, false, 10.0, 5.0};
  auto values = random_values(c, size_t(dims.count()), 9);
  const std::string hdr = nrrd_header("float", "7 6 5", "endian: little\nencoding: gzip") + "\n";
  write_bytes(dir / "g.nrrd", hdr);
  write_gzip(dir / "g.nrrd", encode(DType::Float32, values, false), "ab");
  VolumeDesc d = describe_volume(dir / "g.nrrd");
  ASSERT_EQ(d.encoding, "gzip");
  Volume v = load_volume(d);
  ValueRange r = scan_value_range(d);
  EXPECT_EQ(r.lo, v.lo);
  EXPECT_EQ(r.hi, v.hi);
  expect_bitwise_equal(concatenated_slabs(d, r.lo, r.hi, {}, 2 * 42), v, "gzip");

  // Random access into gzip data is refused with one clear line.
  std::string msg = error_of([&] { RawVolumeFile file(d, r.lo, r.hi, NonFinitePolicy::Error); });
  EXPECT_NE(msg.find("gzip"), std::string::npos) << msg;
  EXPECT_NE(msg.find("uncompressed"), std::string::npos) << msg;
  EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  Network net(preset_config("small"));
  net.init_params(1);
  msg = error_of([&] { evaluate_sampled(net, d, r.lo, r.hi, 100, 1); });
  EXPECT_NE(msg.find("gzip"), std::string::npos) << msg;
  EXPECT_NE(msg.find("sampled evaluation"), std::string::npos) << msg;
  EXPECT_NE(msg.find("without --sample streams"), std::string::npos) << msg;
  EXPECT_EQ(msg.find("vnr convert"), std::string::npos) << msg;  // converts models, not volumes

  // A stream that ends early: load_volume's size message.
  write_bytes(dir / "s.nrrd", hdr);
  write_gzip(dir / "s.nrrd", encode(DType::Float32, values, false).substr(0, 100), "ab");
  VolumeDesc ds = d;
  ds.path = dir / "s.nrrd";
  std::string expected = error_of([&] { load_volume(ds); });
  EXPECT_NE(expected.find("decompresses to 100 bytes"), std::string::npos) << expected;
  EXPECT_EQ(error_of([&] { scan_value_range(ds); }), expected);
  EXPECT_EQ(error_of([&] { for_each_slab(ds, 0, 1, {}, 42, [](int64_t, int64_t, const float*) {}); }), expected);
}

TEST(StreamVolume, ShortRawFileIsAClearError) {
  TmpDir dir;
  const Int3 dims{8, 8, 8};
  const Case c{DType::UInt16, false, 0, 4000};
  auto values = random_values(c, size_t(dims.count()), 5);
  const std::string path = dir / "v.raw";
  VolumeDesc d = write_raw(path, c, dims, values);
  fs::resize_file(path, 700);  // the file shrank after it was described
  std::string expected = error_of([&] { load_volume(d); });
  EXPECT_NE(expected.find("unexpected end of file"), std::string::npos) << expected;
  EXPECT_EQ(error_of([&] { scan_value_range(d); }), expected);
  int calls = 0;
  auto count_calls = [&](int64_t, int64_t, const float*) { ++calls; };
  std::string msg = error_of([&] { for_each_slab(d, 0, 4000, {}, 64, count_calls); });
  EXPECT_NE(msg.find("unexpected end of file"), std::string::npos) << msg;
  EXPECT_EQ(calls, 5);  // 700 bytes hold 5 whole slices of 64 uint16 voxels
  msg = error_of([&] { RawVolumeFile file(d, 0, 4000, NonFinitePolicy::Error); });
  EXPECT_NE(msg.find("is 700 bytes, expected at least 1024"), std::string::npos) << msg;
}

TEST(StreamVolume, NonFiniteValuesFollowLoadVolumesPolicy) {
  TmpDir dir;
  const Int3 dims{5, 4, 6};
  const Case c{DType::Float32, true, -2.0, 9.0};
  auto values = random_values(c, size_t(dims.count()), 11);
  values[0] = std::numeric_limits<double>::quiet_NaN();  // before the first finite value: pivot is values[2]
  values[1] = -std::numeric_limits<double>::infinity();
  values[37] = std::numeric_limits<double>::infinity();
  values[80] = std::numeric_limits<double>::quiet_NaN();
  VolumeDesc d = write_raw(dir / "v.raw", c, dims, values);

  // Error: the same message (count and first voxel) from every reader.
  std::string expected = error_of([&] { load_volume(d); });
  EXPECT_NE(expected.find("contains 4 NaN/Inf values (first at voxel (0,0,0))"), std::string::npos) << expected;
  EXPECT_EQ(error_of([&] { scan_value_range(d); }), expected);
  int calls = 0;
  EXPECT_EQ(error_of([&] { for_each_slab(d, -2, 7, {}, 20 * 2, [&](int64_t, int64_t, const float*) { ++calls; }); }),
            expected);
  EXPECT_EQ(calls, 0);  // the first slab already holds a NaN
  RawVolumeFile strict(d, -2, 7, NonFinitePolicy::Error);
  const int64_t bad = 37, good = 3;
  float out = -1;
  std::string msg = error_of([&] { strict.read_voxels(&bad, 1, &out); });
  EXPECT_NE(msg.find("voxel (2,3,1)"), std::string::npos) << msg;
  EXPECT_NO_THROW(strict.read_voxels(&good, 1, &out));
  // A block read (two rows in one pread) names the same voxel.
  std::vector<float> box(3 * 2);
  std::vector<unsigned char> scratch(strict.scratch_bytes(Int3{3, 2, 1}));
  msg = error_of([&] { strict.read_box(Int3{1, 2, 1}, Int3{3, 2, 1}, box.data(), scratch.data()); });
  EXPECT_NE(msg.find("voxel (2,3,1)"), std::string::npos) << msg;

  for (NonFinitePolicy p : {NonFinitePolicy::Zero, NonFinitePolicy::Clamp}) {
    LoadOptions o;
    o.non_finite = p;
    Volume v = load_volume(d, o);
    ValueRange r = scan_value_range(d, o);
    EXPECT_EQ(r.lo, v.lo);
    EXPECT_EQ(r.hi, v.hi);
    expect_bitwise_equal(concatenated_slabs(d, r.lo, r.hi, o, 20 * 4), v, "policy");
    RawVolumeFile file(d, r.lo, r.hi, p);
    std::vector<int64_t> idx = {37, 0, 1, 80, 5, 119};
    std::vector<float> got(idx.size());
    file.read_voxels(idx.data(), int64_t(idx.size()), got.data());
    for (size_t i = 0; i < idx.size(); ++i) EXPECT_EQ(got[i], v.data[size_t(idx[i])]) << idx[i];
  }
}

TEST(StreamVolume, ReadVoxelsEqualsLoadVolumeBitForBit) {
  TmpDir dir;
  const Int3 dims{31, 17, 12};
  int k = 0;
  for (const Case& c : kCases) {
    SCOPED_TRACE(std::string(dtype_name(c.dtype)) + (c.big ? " big" : " little"));
    auto values = random_values(c, size_t(dims.count()), uint64_t(200 + k));
    RawOptions o;
    o.offset = 3;  // a header before the data
    std::string bytes = "hdr" + encode(c.dtype, values, c.big);
    const std::string path = dir / (std::to_string(k++) + ".raw");
    write_bytes(path, bytes);
    o.dims = dims;
    o.dtype = dtype_name(c.dtype);
    o.endian = c.big ? "big" : "little";
    VolumeDesc d = describe_volume(path, o);
    Volume v = load_volume(d);
    RawVolumeFile file(d, v.lo, v.hi, NonFinitePolicy::Error);
    EXPECT_EQ(file.voxel_count(), int64_t(dims.count()));
    // Random order with repeats, plus both ends of the file.
    Pcg32 rng(7);
    std::vector<int64_t> idx(3000);
    for (auto& i : idx) i = int64_t(rng.next_uint() % dims.count());
    idx.push_back(0);
    idx.push_back(int64_t(dims.count()) - 1);
    std::vector<float> got(idx.size());
    file.read_voxels(idx.data(), int64_t(idx.size()), got.data());
    for (size_t i = 0; i < idx.size(); ++i)
      ASSERT_EQ(std::memcmp(&got[i], &v.data[size_t(idx[i])], sizeof(float)), 0) << "voxel " << idx[i];
  }
  const int64_t outside = 1 << 30;
  float out;
  Case c = kCases[0];
  VolumeDesc d = write_raw(dir / "u8.raw", c, dims, random_values(c, size_t(dims.count()), 1));
  RawVolumeFile file(d, 0, 255, NonFinitePolicy::Error);
  EXPECT_NE(error_of([&] { file.read_voxels(&outside, 1, &out); }).find("out of range"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// Streamed and sampled evaluation

TEST(StreamEval, DecodeVoxelsEqualsDecodeSlices) {
  auto net = varied_network(3);
  const Int3 dims{19, 13, 11};
  std::vector<float> all(dims.count());
  decode_slices(*net, dims, 0, dims.z, all.data());
  Pcg32 rng(5);
  std::vector<int64_t> idx(1001);
  for (auto& i : idx) i = int64_t(rng.next_uint() % dims.count());
  std::vector<float> got(idx.size());
  decode_voxels(*net, dims, idx.data(), int64_t(idx.size()), got.data());
  for (size_t i = 0; i < idx.size(); ++i) ASSERT_EQ(got[i], all[size_t(idx[i])]) << idx[i];
}

TEST(StreamEval, StreamedEqualsInMemoryEvaluation) {
  TmpDir dir;
  auto net = varied_network(1);
  struct Vol {
    std::string name;
    Int3 dims;
  };
  // Slab boundaries that do and do not divide nz; a volume thinner than the SSIM window in z (the
  // window is then the whole axis) and one narrower than it in x.
  for (const Vol& t : {Vol{"a", {20, 18, 23}}, Vol{"thin", {16, 12, 5}}, Vol{"narrow", {4, 9, 15}}}) {
    SCOPED_TRACE(t.name);
    const std::string json = dir / (t.name + ".json");
    synth_volume("marschner-lobb", t.dims, json);
    VolumeDesc d = describe_volume(json);
    Volume v = load_volume(d);
    for (bool with_ssim : {true, false}) {
      EvalResult full = evaluate(*net, v, with_ssim);
      const int64_t slice = t.dims.x * t.dims.y;
      for (int64_t slabs : {int64_t(1), int64_t(3), int64_t(7), int64_t(10), int64_t(1000)}) {
        SCOPED_TRACE("slab slices " + std::to_string(slabs) + (with_ssim ? " with SSIM" : ""));
        double last = 0;
        auto progress = [&](double f) { last = f; };
        EvalResult s = evaluate_streamed(*net, d, v.lo, v.hi, {}, with_ssim, progress, slabs * slice);
        EXPECT_EQ(last, 1.0);
        EXPECT_NEAR(s.psnr, full.psnr, 1e-9 * std::fabs(full.psnr));
        EXPECT_NEAR(s.mse, full.mse, 1e-9 * full.mse);
        EXPECT_EQ(s.max_abs_error, full.max_abs_error);
        EXPECT_EQ(s.max_abs_error_original, full.max_abs_error_original);
        if (with_ssim) {
          EXPECT_NEAR(s.ssim, full.ssim, 1e-9 * std::fabs(full.ssim));
        } else {
          EXPECT_EQ(s.ssim, 0.0);
        }
      }
    }
  }
}

// A box of a file evaluated in parts (as MPI ranks evaluate their slices) adds up to evaluate() on the
// box loaded: the same PSNR and max error, and the same SSIM, whose windows cross every part boundary.
TEST(StreamEval, BoxSlicesAddUpToTheEvaluationOfTheLoadedBox) {
  TmpDir dir;
  auto net = varied_network(4);
  const std::string json = dir / "v.json";
  synth_volume("marschner-lobb", Int3{22, 19, 26}, json);
  const VolumeDesc d = describe_volume(json);
  const Volume v = load_volume(d);
  const RawVolumeFile file(d, v.lo, v.hi, NonFinitePolicy::Error);
  const Box3 box{{3, 2, 4}, {20, 19, 21}};  // 17 slices: a thin part holds fewer than a window
  Volume loaded = v;
  loaded.dims = box.size();
  loaded.data.assign(box.voxels(), 0.f);
  std::vector<unsigned char> scratch(file.scratch_bytes(box.size()));
  file.read_box(box.lo, box.size(), loaded.data.data(), scratch.data());
  for (bool with_ssim : {true, false}) {
    SCOPED_TRACE(with_ssim ? "with SSIM" : "without SSIM");
    const EvalResult full = evaluate(*net, loaded, with_ssim);
    for (const std::vector<int64_t>& cuts : {std::vector<int64_t>{0, 17}, {0, 5, 6, 14, 17}, {0, 1, 2, 3, 12, 16, 17}}) {
      for (int64_t slab_slices : {int64_t(1), int64_t(4), int64_t(100)}) {
        EvalSums all;
        for (size_t i = 0; i + 1 < cuts.size(); ++i)
          all.add(evaluate_box_slices(*net, file, box, cuts[i], cuts[i + 1], with_ssim, slab_slices * 17 * 17));
        const EvalResult r = all.result(v.hi - v.lo);
        EXPECT_EQ(all.voxels, int64_t(box.voxels()));
        EXPECT_NEAR(r.psnr, full.psnr, 1e-9 * std::fabs(full.psnr));
        EXPECT_EQ(r.max_abs_error, full.max_abs_error);
        EXPECT_EQ(r.max_abs_error_original, full.max_abs_error_original);
        EXPECT_NEAR(r.ssim, full.ssim, with_ssim ? 1e-12 : 0.0);
        if (with_ssim) EXPECT_EQ(all.ssim_windows, int64_t(11 * 11 * 11));
      }
    }
  }
  EXPECT_THROW(evaluate_box_slices(*net, file, Box3{{0, 0, 0}, {23, 19, 26}}, 0, 26, false), Error);  // past the volume
  EXPECT_THROW(evaluate_box_slices(*net, file, box, 3, 18, false), Error);                           // past the box
}

TEST(StreamEval, StreamedEvaluationOfAnIntegerVolumeWithScannedRange) {
  // uint8 without a sidecar range: the range comes from scan_value_range, the values from slabs.
  TmpDir dir;
  auto net = varied_network(2);
  const Int3 dims{17, 15, 14};
  const Case c{DType::UInt8, false, 10, 200};
  VolumeDesc d = write_raw(dir / "u8.raw", c, dims, random_values(c, size_t(dims.count()), 4));
  Volume v = load_volume(d);
  EvalResult full = evaluate(*net, v, true);
  ValueRange r = scan_value_range(d);
  EvalResult s = evaluate_streamed(*net, d, r.lo, r.hi, {}, true, {}, 2 * dims.x * dims.y);
  EXPECT_NEAR(s.psnr, full.psnr, 1e-9 * std::fabs(full.psnr));
  EXPECT_EQ(s.max_abs_error, full.max_abs_error);
  EXPECT_EQ(s.max_abs_error_original, full.max_abs_error_original);
  EXPECT_NEAR(s.ssim, full.ssim, 1e-9);
}

TEST(StreamEval, SampledPsnrIntervalContainsTheFullPsnr) {
  TmpDir dir;
  auto net = varied_network(4);
  const Int3 dims{48, 40, 36};
  const std::string json = dir / "ml.json";
  synth_volume("marschner-lobb", dims, json);
  VolumeDesc d = describe_volume(json);
  Volume v = load_volume(d);
  EvalResult full = evaluate(*net, v, false);

  SampledEval s = evaluate_sampled(*net, d, v.lo, v.hi, 20000, 1);
  EXPECT_EQ(s.samples, 20000);
  EXPECT_LT(s.psnr_ci95_lo, s.psnr);
  EXPECT_GT(s.psnr_ci95_hi, s.psnr);
  EXPECT_LE(s.psnr_ci95_lo, full.psnr);
  EXPECT_GE(s.psnr_ci95_hi, full.psnr);
  EXPECT_LT(s.psnr_ci95_hi - s.psnr_ci95_lo, 0.5);  // 20000 samples: a useful interval
  EXPECT_GT(s.mse_stderr, 0);
  EXPECT_LE(s.max_abs_error, full.max_abs_error);  // the samples are voxels of the full evaluation
  EXPECT_GT(s.max_abs_error, 0.5 * full.max_abs_error);
  EXPECT_DOUBLE_EQ(s.max_abs_error_original, s.max_abs_error * (v.hi - v.lo));

  // Deterministic for a seed, different for another.
  SampledEval again = evaluate_sampled(*net, d, v.lo, v.hi, 20000, 1);
  EXPECT_EQ(again.psnr, s.psnr);
  EXPECT_EQ(again.psnr_ci95_lo, s.psnr_ci95_lo);
  EXPECT_EQ(again.max_abs_error, s.max_abs_error);
  EXPECT_NE(evaluate_sampled(*net, d, v.lo, v.hi, 20000, 2).psnr, s.psnr);

  // Many samples (more than one batch of draws; 20x the voxel count): close to the exact value.
  SampledEval many = evaluate_sampled(*net, d, v.lo, v.hi, int64_t(dims.count()) * 20, 3);
  EXPECT_NEAR(many.psnr, full.psnr, 0.02);
  EXPECT_LT(many.psnr_ci95_hi - many.psnr_ci95_lo, 0.05);
  EXPECT_EQ(many.max_abs_error, full.max_abs_error);  // every voxel is drawn at least once, surely

  EXPECT_NE(error_of([&] { evaluate_sampled(*net, d, v.lo, v.hi, 0, 1); }).find("positive"), std::string::npos);
}

TEST(StreamEval, SampledIntervalCoversTheFullPsnrAbout95PercentOfTheTime) {
  // The interval is a 95% one: over many seeds about 5% of them must miss (too few misses would
  // mean a needlessly wide interval, too many a wrong standard error).
  TmpDir dir;
  auto net = varied_network(6);
  const Int3 dims{32, 30, 28};
  const std::string json = dir / "n.json";
  synth_volume("noise", dims, json, 3);
  VolumeDesc d = describe_volume(json);
  Volume v = load_volume(d);
  const double psnr = evaluate(*net, v, false).psnr;
  int inside = 0;
  const int trials = 300;
  for (int seed = 0; seed < trials; ++seed) {
    SampledEval e = evaluate_sampled(*net, d, v.lo, v.hi, 4000, uint64_t(seed));
    inside += e.psnr_ci95_lo <= psnr && psnr <= e.psnr_ci95_hi;
  }
  RecordProperty("inside", inside);
  EXPECT_GE(inside, int(0.90 * trials));  // binomial(300, 0.95): mean 285, sd 3.8
  EXPECT_LE(inside, int(0.99 * trials));
}
