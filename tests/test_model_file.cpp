#include <gtest/gtest.h>
#include <dirent.h>
#include <sys/stat.h>
#include <unistd.h>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/core/half.h"
#include "vnr/nn/model_file.h"
#include "test_support.h"

using namespace vnr;
using namespace vnr::test;

namespace {

std::vector<std::string> list_dir(const std::string& dir) {
  std::vector<std::string> out;
  if (DIR* d = ::opendir(dir.c_str())) {
    while (dirent* e = ::readdir(d))
      if (std::strcmp(e->d_name, ".") && std::strcmp(e->d_name, "..")) out.push_back(e->d_name);
    ::closedir(d);
  }
  return out;
}

Json example_config() {
  return Json::parse(R"({
    "optimizer": {"otype": "ExponentialDecay", "decay_start": 2000, "decay_interval": 1000, "decay_base": 0.99,
                  "nested": {"otype": "Adam", "learning_rate": 5e-3, "beta1": 0.9, "beta2": 0.999,
                             "epsilon": 1e-15, "l2_reg": 1e-6}},
    "loss": {"otype": "L1"},
    "encoding": {"otype": "HashGrid", "n_levels": 8, "n_features_per_level": 8, "log2_hashmap_size": 19,
                 "base_resolution": 16, "per_level_scale": 1.3195079565048218},
    "network": {"otype": "FullyFusedMLP", "activation": "ReLU", "n_neurons": 64, "n_hidden_layers": 4,
                "output_activation": "None"}
  })");
}

// A model with random fp16 bits (NaN/inf patterns included: the block is opaque bits) and
// macro-cells on instantvnr's 16-voxel grid. dyadic=true keeps ranges at multiples of 2^-10 so the
// BSON (min-1, max+1) encoding is exact.
ModelFile make_model(uint32_t seed, size_t n_params, Int3 dims, bool macrocells = true, bool dyadic = false) {
  std::mt19937 rng(seed);
  ModelFile m;
  m.config = example_config();
  m.dims = dims;
  m.source_dtype = DType::UInt16;
  m.lo = -3.25;
  m.hi = 100000.1;
  m.params.resize(n_params);
  for (auto& p : m.params) p = uint16_t(rng());
  if (macrocells) {
    m.macrocell_dims = {(dims.x + 15) / 16, (dims.y + 15) / 16, (dims.z + 15) / 16};
    m.macrocell_ranges.resize(2 * m.macrocell_dims.count());
    for (size_t i = 0; i < m.macrocell_ranges.size(); i += 2) {
      float a, b;
      if (dyadic) {
        a = float(rng() % 1025) / 1024.0f;
        b = float(rng() % 1025) / 1024.0f;
      } else {
        a = std::uniform_real_distribution<float>(0, 1)(rng);
        b = std::uniform_real_distribution<float>(0, 1)(rng);
      }
      m.macrocell_ranges[i] = std::min(a, b);
      m.macrocell_ranges[i + 1] = std::max(a, b);
    }
    m.macrocell_ranges[0] = 1.0f;  // an empty cell, as instantvnr leaves untouched cells
    m.macrocell_ranges[1] = -1.0f;
  }
  m.training = Json{{"steps", 20000}, {"seconds", 12.5}, {"psnr", 41.234567890123}, {"note", "unit test"}};
  return m;
}

bool contains(const std::string& s, const std::string& sub) { return s.find(sub) != std::string::npos; }

// Minimal BSON walker: element type (and binary subtype) per dotted key path, to check what
// nlohmann's from_bson hides (int32 vs int64).
struct BsonTypes {
  std::map<std::string, uint8_t> type, subtype;
};
void walk_bson(const std::string& b, size_t off, const std::string& prefix, BsonTypes& out) {
  int32_t len;
  std::memcpy(&len, b.data() + off, 4);
  ASSERT_LE(off + size_t(len), b.size());
  size_t p = off + 4;
  while (b[p] != 0) {
    uint8_t t = uint8_t(b[p++]);
    std::string key(b.data() + p);
    p += key.size() + 1;
    std::string path = prefix + key;
    out.type[path] = t;
    int32_t n;
    switch (t) {
      case 0x01: case 0x11: case 0x12: p += 8; break;
      case 0x10: p += 4; break;
      case 0x08: p += 1; break;
      case 0x0A: break;
      case 0x02: std::memcpy(&n, b.data() + p, 4); p += 4 + size_t(n); break;
      case 0x03: case 0x04:
        walk_bson(b, p, path + ".", out);
        std::memcpy(&n, b.data() + p, 4);
        p += size_t(n);
        break;
      case 0x05:
        std::memcpy(&n, b.data() + p, 4);
        out.subtype[path] = uint8_t(b[p + 4]);
        p += 5 + size_t(n);
        break;
      default: FAIL() << "unexpected BSON type " << int(t) << " at " << path;
    }
  }
  EXPECT_EQ(p + 1, off + size_t(len));
}

void expect_same(const ModelFile& a, const ModelFile& b) {
  EXPECT_EQ(a.config, b.config);
  EXPECT_EQ(a.dims, b.dims);
  EXPECT_EQ(a.source_dtype, b.source_dtype);
  EXPECT_EQ(a.lo, b.lo);
  EXPECT_EQ(a.hi, b.hi);
  EXPECT_EQ(a.params, b.params);  // uint16 bit patterns: exact, NaNs included
  EXPECT_EQ(a.macrocell_dims, b.macrocell_dims);
  ASSERT_EQ(a.macrocell_ranges.size(), b.macrocell_ranges.size());
  if (!a.macrocell_ranges.empty())  // memcmp on an empty vector's null data() is undefined (UBSan)
    EXPECT_EQ(0, std::memcmp(a.macrocell_ranges.data(), b.macrocell_ranges.data(), a.macrocell_ranges.size() * 4));
  EXPECT_EQ(a.training, b.training);
}

}  // namespace

// ---- native .vnr ------------------------------------------------------------------------------

TEST(VnrFile, RoundTripIsExact) {
  TmpDir tmp;
  std::string dir = tmp.str(), path = dir + "/m.vnr";
  ModelFile m = make_model(1, 5001, {37, 20, 9});
  write_vnr(path, m);
  expect_same(m, read_vnr(path));
  expect_same(m, read_model(path));
  EXPECT_EQ(list_dir(dir), std::vector<std::string>{"m.vnr"});  // no temporary left behind
}

TEST(VnrFile, RoundTripWithoutOptionalParts) {
  TmpDir tmp;
  std::string path = tmp / "m.vnr";
  ModelFile m = make_model(2, 0, {1, 1, 1}, /*macrocells=*/false);
  m.training = nullptr;
  m.source_dtype = DType::Float64;
  write_vnr(path, m);
  ModelFile r = read_vnr(path);
  expect_same(m, r);
  EXPECT_EQ(r.macrocell_dims, (Int3{0, 0, 0}));
  EXPECT_TRUE(r.training.is_null());
}

TEST(VnrFile, ByteLayoutMatchesDocumentation) {
  TmpDir tmp;
  std::string path = tmp / "m.vnr";
  ModelFile m = make_model(3, 123, {40, 16, 17});
  write_vnr(path, m);
  std::string b = read_file(path);
  ASSERT_GE(b.size(), 36u);
  EXPECT_EQ(b.substr(0, 8), "VNRMODEL");
  uint32_t version, flags, crc;
  uint64_t hbytes;
  std::memcpy(&version, b.data() + 8, 4);
  std::memcpy(&flags, b.data() + 12, 4);
  std::memcpy(&hbytes, b.data() + 16, 8);
  EXPECT_EQ(version, 1u);
  EXPECT_EQ(flags, 0u);
  Json h = Json::parse(b.substr(24, hbytes));
  EXPECT_EQ(h["config"], m.config);
  EXPECT_EQ(h["dims"], Json::array({40, 16, 17}));
  EXPECT_EQ(h["dtype"], "uint16");
  EXPECT_EQ(h["value_range"], Json::array({m.lo, m.hi}));
  EXPECT_EQ(h["n_params"], 123);
  EXPECT_EQ(h["params_dtype"], "float16");
  EXPECT_EQ(h["macrocell_dims"], Json::array({3, 1, 2}));
  EXPECT_EQ(h["training"], m.training);
  EXPECT_TRUE(h["vnr_version"].is_string());
  uint64_t params_off = next_multiple(24 + hbytes, 64);
  for (uint64_t i = 24 + hbytes; i < params_off; ++i) EXPECT_EQ(b[i], 0);
  EXPECT_EQ(0, std::memcmp(b.data() + params_off, m.params.data(), 2 * 123));
  uint64_t mc_off = next_multiple(params_off + 2 * 123, 64);
  EXPECT_EQ(0, std::memcmp(b.data() + mc_off, m.macrocell_ranges.data(), 4 * m.macrocell_ranges.size()));
  uint64_t end = mc_off + 4 * m.macrocell_ranges.size();
  ASSERT_EQ(b.size(), end + 12);
  std::memcpy(&crc, b.data() + end, 4);
  EXPECT_EQ(crc, crc32_of(b.data(), end));
  EXPECT_EQ(b.substr(end + 4), std::string("VNREND\0\0", 8));
}

TEST(VnrFile, TruncatedFilesAreReported) {
  TmpDir tmp;
  std::string dir = tmp.str(), path = dir + "/m.vnr", cut = dir + "/cut.vnr";
  write_vnr(path, make_model(4, 777, {33, 17, 5}));
  std::string b = read_file(path);
  uint64_t hbytes;
  std::memcpy(&hbytes, b.data() + 16, 8);
  std::vector<size_t> lengths = {0, 1, 5, 8, 12, 20, 24, 30, size_t(24 + hbytes / 2), size_t(24 + hbytes),
                                 size_t(24 + hbytes + 13), b.size() / 2, b.size() - 13, b.size() - 12,
                                 b.size() - 8, b.size() - 1};
  for (size_t len : lengths) {
    SCOPED_TRACE(len);
    write_bytes(cut, b.substr(0, len));
    std::string msg = error_of([&] { read_vnr(cut); });
    EXPECT_TRUE(contains(msg, "is truncated")) << msg;
    EXPECT_FALSE(contains(msg, "\n"));
    // Once the header is whole, the message names the exact expected size.
    if (len >= 24 + hbytes + 12)
      EXPECT_TRUE(contains(msg, fmt::format("expected {} bytes, found {}", b.size(), len))) << msg;
    if (len > 0) EXPECT_EQ(error_of([&] { read_model(cut); }), msg);
  }
}

TEST(VnrFile, FlippedParamByteIsAChecksumError) {
  TmpDir tmp;
  std::string path = tmp / "m.vnr";
  ModelFile m = make_model(5, 1000, {16, 16, 16});
  write_vnr(path, m);
  std::string b = read_file(path);
  uint64_t hbytes;
  std::memcpy(&hbytes, b.data() + 16, 8);
  b[next_multiple(24 + hbytes, 64) + 501] ^= 0x10;
  write_bytes(path, b);
  EXPECT_EQ(error_of([&] { read_vnr(path); }), fmt::format("'{}' is corrupted (checksum mismatch)", path));
}

TEST(VnrFile, WrongMagicAndNewerVersion) {
  TmpDir tmp;
  std::string dir = tmp.str(), path = dir + "/m.vnr";
  write_vnr(path, make_model(6, 10, {8, 8, 8}));
  std::string b = read_file(path);

  std::string bad = b;
  bad[3] = 'X';
  write_bytes(path, bad);
  EXPECT_EQ(error_of([&] { read_vnr(path); }), fmt::format("'{}' is not a vnr model file", path));

  std::string newer = b;
  newer[8] = 4;  // a future writer would also recompute the CRC; the version check must come first
  write_bytes(path, newer);
  std::string msg = error_of([&] { read_vnr(path); });
  EXPECT_TRUE(contains(msg, "written by a newer vnr (format 4 > 3)")) << msg;
  EXPECT_EQ(error_of([&] { read_model(path); }), msg);

  // Neither format: read_model says so on one line.
  write_bytes(path, "this is plain text, not a model at all");
  msg = error_of([&] { read_model(path); });
  EXPECT_TRUE(contains(msg, "neither a vnr model file nor an instantvnr params file")) << msg;
  EXPECT_FALSE(contains(msg, "\n"));
  write_bytes(path, "");
  EXPECT_TRUE(contains(error_of([&] { read_model(path); }), "is empty"));
  EXPECT_TRUE(contains(error_of([&] { read_vnr(dir + "/missing.vnr"); }), "cannot open"));
}

TEST(VnrFile, InvalidModelsAreRejectedOnWrite) {
  TmpDir tmp;
  std::string path = tmp / "m.vnr";
  ModelFile m = make_model(7, 10, {8, 8, 8});
  m.macrocell_ranges.pop_back();
  EXPECT_TRUE(contains(error_of([&] { write_vnr(path, m); }), "macro-cell values"));
  m = make_model(7, 10, {8, 8, 8});
  m.dims.y = 0;
  EXPECT_TRUE(contains(error_of([&] { write_vnr(path, m); }), "invalid volume dims"));
  EXPECT_TRUE(contains(error_of([&] { write_instantvnr(path, m); }), "invalid volume dims"));
  m = make_model(7, 10, {8, 8, 8});
  m.hi = NAN;
  EXPECT_TRUE(contains(error_of([&] { write_vnr(path, m); }), "not finite"));
  EXPECT_FALSE(file_exists(path));
}

TEST(VnrFile, FailedWritesLeaveOldFileAndNoTemporaries) {
  TmpDir tmp;
  std::string dir = tmp.str(), path = dir + "/m.vnr";
  ModelFile old_model = make_model(8, 64, {8, 8, 8});
  write_vnr(path, old_model);
  std::string before = read_file(path);

  // 1. Target directory does not exist: nothing is created anywhere.
  EXPECT_TRUE(contains(error_of([&] { write_vnr(dir + "/no/such/dir/m.vnr", old_model); }), "cannot write"));
  // 2. Invalid model over an existing file: refused before the temporary is opened.
  ModelFile bad = make_model(9, 64, {8, 8, 8});
  bad.macrocell_ranges.resize(3);
  EXPECT_THROW(write_vnr(path, bad), Error);
  EXPECT_THROW(write_instantvnr(path, bad), Error);
  // 3. Failure at the very end (the rename onto a directory fails after all data was written).
  std::string sub = dir + "/occupied";
  ::mkdir(sub.c_str(), 0755);
  EXPECT_TRUE(contains(error_of([&] { write_vnr(sub, old_model); }), "cannot write"));
  EXPECT_TRUE(contains(error_of([&] { write_instantvnr(sub, old_model); }), "cannot write"));
  // 4. Read-only directory (only meaningful when not running as root).
  std::string ro = dir + "/ro";
  ::mkdir(ro.c_str(), 0755);
  write_vnr(ro + "/m.vnr", old_model);
  ::chmod(ro.c_str(), 0555);
  if (::geteuid() != 0) {
    EXPECT_THROW(write_vnr(ro + "/m.vnr", make_model(10, 64, {8, 8, 8})), Error);
    expect_same(old_model, read_vnr(ro + "/m.vnr"));
  }
  ::chmod(ro.c_str(), 0755);

  EXPECT_EQ(read_file(path), before);
  std::set<std::string> names;
  for (auto& n : list_dir(dir)) names.insert(n);
  EXPECT_EQ(names, (std::set<std::string>{"m.vnr", "occupied", "ro"}));
  EXPECT_TRUE(list_dir(sub).empty());
  EXPECT_EQ(list_dir(ro), std::vector<std::string>{"m.vnr"});
}

TEST(VnrFile, FuzzedFilesAlwaysFailCleanly) {
  TmpDir tmp;
  std::string dir = tmp.str(), path = dir + "/m.vnr", bad = dir + "/bad.vnr";
  write_vnr(path, make_model(11, 300, {20, 20, 12}));
  const std::string b = read_file(path);
  std::mt19937 rng(12345);
  for (int i = 0; i < 200; ++i) {
    std::string c = b;
    size_t pos = rng() % c.size();
    c[pos] = char(uint8_t(c[pos]) ^ uint8_t(1 + rng() % 255));  // always a real change
    write_bytes(bad, c);
    SCOPED_TRACE(pos);
    EXPECT_THROW(read_vnr(bad), Error);
    EXPECT_THROW(read_model(bad), Error);
  }
  for (int i = 0; i < 50; ++i) {
    size_t len = rng() % b.size();
    write_bytes(bad, b.substr(0, len));
    SCOPED_TRACE(len);
    EXPECT_THROW(read_vnr(bad), Error);
    EXPECT_THROW(read_model(bad), Error);
  }
}

// ---- instantvnr BSON --------------------------------------------------------------------------

TEST(InstantVnrFile, BsonStructureMatchesInstantVnr) {
  TmpDir tmp;
  std::string path = tmp / "params.json";
  ModelFile m = make_model(20, 2049, {37, 20, 9});
  write_instantvnr(path, m);
  std::string raw = read_file(path);
  Json j = Json::from_bson(raw.begin(), raw.end());

  std::set<std::string> keys;
  for (auto& [k, v] : j.items()) keys.insert(k);
  EXPECT_EQ(keys, (std::set<std::string>{"macrocell", "model", "parameters", "volume"}));
  EXPECT_EQ(j["volume"]["dims"], (Json{{"x", 37}, {"y", 20}, {"z", 9}}));

  // model: loss/encoding/network only, copied from the config.
  EXPECT_EQ(j["model"].size(), 3u);
  EXPECT_EQ(j["model"]["loss"], m.config["loss"]);
  EXPECT_EQ(j["model"]["encoding"], m.config["encoding"]);
  EXPECT_EQ(j["model"]["network"], m.config["network"]);
  EXPECT_FALSE(j["model"].contains("optimizer"));

  // parameters: raw fp16 little-endian bytes, BSON binary subtype 0.
  EXPECT_EQ(j["parameters"]["n_params"], 2049);
  const auto& pb = j["parameters"]["params_binary"].get_binary();
  EXPECT_TRUE(pb.has_subtype());
  EXPECT_EQ(pb.subtype(), 0u);
  ASSERT_EQ(pb.size(), 2u * 2049);
  EXPECT_EQ(0, std::memcmp(pb.data(), m.params.data(), pb.size()));

  // macrocell: ceil(dims/16) cells, float spacings 16/dims, (min-1, max+1) pairs.
  const Json& mc = j["macrocell"];
  EXPECT_EQ(mc["groundtruth"], false);
  EXPECT_EQ(mc["dims"], (Json{{"x", 3}, {"y", 2}, {"z", 1}}));
  const char* axes[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    double s = mc["spacings"][axes[a]].get<double>();
    EXPECT_EQ(s, double(16.0f / float(m.dims[a])));  // what instantvnr's float math produces
    EXPECT_NEAR(s, 16.0 / double(m.dims[a]), 1e-6);
  }
  const auto& data = mc["data"].get_binary();
  EXPECT_EQ(data.subtype(), 0u);
  ASSERT_EQ(data.size(), 4 * m.macrocell_ranges.size());
  std::vector<float> enc(m.macrocell_ranges.size());
  std::memcpy(enc.data(), data.data(), data.size());
  for (size_t i = 0; i < enc.size(); i += 2) {
    EXPECT_EQ(enc[i], m.macrocell_ranges[i] - 1.0f);
    EXPECT_EQ(enc[i + 1], m.macrocell_ranges[i + 1] + 1.0f);
  }
  EXPECT_EQ(enc[0], 0.0f);  // the empty cell (1,-1) is instantvnr's untouched (0,0)
  EXPECT_EQ(enc[1], 0.0f);

  // Raw element types: integers are int32 (0x10), spacings doubles, data binary subtype 0.
  BsonTypes t;
  walk_bson(raw, 0, "", t);
  for (const char* k : {"volume.dims.x", "volume.dims.y", "volume.dims.z", "macrocell.dims.x", "macrocell.dims.z",
                        "parameters.n_params", "model.encoding.n_levels", "model.network.n_neurons"})
    EXPECT_EQ(t.type[k], 0x10) << k;
  for (const char* k : {"macrocell.spacings.x", "macrocell.spacings.y", "macrocell.spacings.z",
                        "model.encoding.per_level_scale"})
    EXPECT_EQ(t.type[k], 0x01) << k;
  EXPECT_EQ(t.type["macrocell.groundtruth"], 0x08);
  EXPECT_EQ(t.type["macrocell.data"], 0x05);
  EXPECT_EQ(t.subtype["macrocell.data"], 0x00);
  EXPECT_EQ(t.type["parameters.params_binary"], 0x05);
  EXPECT_EQ(t.subtype["parameters.params_binary"], 0x00);
  EXPECT_EQ(t.type["model.loss.otype"], 0x02);
  for (auto& [k, ty] : t.type) EXPECT_NE(ty, 0x12) << k;  // nothing here needs int64
}

TEST(InstantVnrFile, NonStandardMacrocellGridGetsEvenSpacing) {
  TmpDir tmp;
  std::string path = tmp / "params.json";
  ModelFile m = make_model(21, 8, {64, 64, 64});
  m.macrocell_dims = {2, 4, 8};
  m.macrocell_ranges.assign(2 * 64, 0.5f);
  write_instantvnr(path, m);
  std::string raw = read_file(path);
  Json j = Json::from_bson(raw.begin(), raw.end());
  EXPECT_EQ(j["macrocell"]["spacings"]["x"].get<double>(), 0.5);
  EXPECT_EQ(j["macrocell"]["spacings"]["y"].get<double>(), 0.25);
  EXPECT_EQ(j["macrocell"]["spacings"]["z"].get<double>(), 0.125);
}

TEST(InstantVnrFile, RoundTrip) {
  TmpDir tmp;
  std::string path = tmp / "params.json";
  ModelFile m = make_model(22, 4097, {50, 33, 16}, true, /*dyadic=*/true);
  write_instantvnr(path, m);
  for (const ModelFile& r : {read_instantvnr(path), read_model(path)}) {
    EXPECT_EQ(r.params, m.params);
    EXPECT_EQ(r.dims, m.dims);
    EXPECT_EQ(r.macrocell_dims, m.macrocell_dims);
    EXPECT_EQ(r.macrocell_ranges, m.macrocell_ranges);  // dyadic values survive (min-1, max+1) exactly
    // The config is rebuilt from "model" plus the paper's optimizer (the same as example_config's).
    EXPECT_EQ(r.config, m.config);
    EXPECT_EQ(r.source_dtype, DType::Float32);
    EXPECT_EQ(r.lo, 0.0);
    EXPECT_EQ(r.hi, 1.0);
    EXPECT_TRUE(r.training.is_null());
  }
}

TEST(InstantVnrFile, NoMacrocellsMeansNoMacrocellKey) {
  TmpDir tmp;
  std::string path = tmp / "params.json";
  ModelFile m = make_model(23, 16, {8, 8, 8}, /*macrocells=*/false);
  write_instantvnr(path, m);
  std::string raw = read_file(path);
  EXPECT_FALSE(Json::from_bson(raw.begin(), raw.end()).contains("macrocell"));
  ModelFile r = read_instantvnr(path);
  EXPECT_EQ(r.macrocell_dims, (Int3{0, 0, 0}));
  EXPECT_TRUE(r.macrocell_ranges.empty());
  EXPECT_EQ(r.params, m.params);
}

TEST(InstantVnrFile, VnrToBsonToVnrKeepsParamsAndMacrocells) {
  TmpDir tmp;
  std::string dir = tmp.str();
  for (bool dyadic : {true, false}) {
    ModelFile m = make_model(24, 3000, {70, 40, 20}, true, dyadic);
    write_vnr(dir + "/a.vnr", m);
    write_instantvnr(dir + "/b.json", read_model(dir + "/a.vnr"));
    ModelFile back = read_model(dir + "/b.json");
    write_vnr(dir + "/c.vnr", back);
    ModelFile c = read_model(dir + "/c.vnr");
    EXPECT_EQ(c.params, m.params);
    EXPECT_EQ(c.dims, m.dims);
    EXPECT_EQ(c.macrocell_dims, m.macrocell_dims);
    ASSERT_EQ(c.macrocell_ranges.size(), m.macrocell_ranges.size());
    for (size_t i = 0; i < c.macrocell_ranges.size(); ++i) {
      if (dyadic) EXPECT_EQ(c.macrocell_ranges[i], m.macrocell_ranges[i]);
      else EXPECT_NEAR(c.macrocell_ranges[i], m.macrocell_ranges[i], 1.2e-7);
    }
    EXPECT_EQ(c.config["encoding"], m.config["encoding"]);
    EXPECT_EQ(c.config["network"], m.config["network"]);
  }
}

TEST(InstantVnrFile, LegacyRootLevelParameters) {
  TmpDir tmp;
  std::string path = tmp / "old.json";
  std::vector<uint16_t> params = {0x3c00, 0xc000, 0x0001, 0x7bff, 0x8000};
  std::vector<uint8_t> bytes(params.size() * 2);
  std::memcpy(bytes.data(), params.data(), bytes.size());
  Json root = {{"n_params", 5}, {"params_binary", Json::binary(bytes)}};
  auto bson = Json::to_bson(root);
  write_bytes(path, std::string(bson.begin(), bson.end()));
  for (const ModelFile& r : {read_instantvnr(path), read_model(path)}) {
    EXPECT_EQ(r.params, params);
    EXPECT_EQ(r.dims, (Int3{0, 0, 0}));  // legacy file without "volume"
    EXPECT_EQ(r.macrocell_dims, (Int3{0, 0, 0}));
    EXPECT_EQ(r.config["optimizer"]["otype"], "ExponentialDecay");
    EXPECT_EQ(r.config["optimizer"]["decay_start"], 2000);
    EXPECT_EQ(r.config["optimizer"]["decay_interval"], 1000);
    EXPECT_EQ(r.config["optimizer"]["decay_base"], 0.99);
    EXPECT_EQ(r.config["optimizer"]["nested"],
              (Json{{"otype", "Adam"}, {"learning_rate", 0.005}, {"beta1", 0.9}, {"beta2", 0.999},
                    {"epsilon", 1e-15}, {"l2_reg", 1e-6}}));
  }
}

TEST(InstantVnrFile, FloatParamsAreConvertedToHalf) {
  TmpDir tmp;
  std::string path = tmp / "head.json";
  std::vector<float> f = {1.0f, -2.0f, 0.5f};
  std::vector<uint8_t> bytes(12);
  std::memcpy(bytes.data(), f.data(), 12);
  Json root = {{"volume", {{"dims", {{"x", 4}, {"y", 5}, {"z", 6}}}}},
               {"parameters", {{"n_params", 3}, {"params_type", "float"}, {"params_binary", Json::binary(bytes)}}}};
  auto bson = Json::to_bson(root);
  write_bytes(path, std::string(bson.begin(), bson.end()));
  ModelFile r = read_instantvnr(path);
  EXPECT_EQ(r.params, (std::vector<uint16_t>{0x3c00, 0xc000, 0x3800}));
  EXPECT_EQ(r.dims, (Int3{4, 5, 6}));
}

TEST(InstantVnrFile, BadFilesGiveOneLineErrors) {
  TmpDir tmp;
  std::string dir = tmp.str(), path = dir + "/bad.json";
  // params_binary of the wrong size
  Json root = {{"parameters", {{"n_params", 4}, {"params_binary", Json::binary(std::vector<uint8_t>(6))}}}};
  auto bson = Json::to_bson(root);
  write_bytes(path, std::string(bson.begin(), bson.end()));
  EXPECT_EQ(error_of([&] { read_instantvnr(path); }),
            fmt::format("'{}': params_binary holds 6 bytes, expected 2*n_params = 8", path));

  // macrocell data of the wrong size
  root = {{"parameters", {{"n_params", 1}, {"params_binary", Json::binary(std::vector<uint8_t>(2))}}},
          {"macrocell", {{"dims", {{"x", 2}, {"y", 1}, {"z", 1}}}, {"data", Json::binary(std::vector<uint8_t>(8))}}}};
  bson = Json::to_bson(root);
  write_bytes(path, std::string(bson.begin(), bson.end()));
  EXPECT_TRUE(contains(error_of([&] { read_instantvnr(path); }), "macrocell.data holds 8 bytes"));

  // wrong types
  root = {{"parameters", {{"n_params", "many"}, {"params_binary", Json::binary(std::vector<uint8_t>(2))}}}};
  bson = Json::to_bson(root);
  write_bytes(path, std::string(bson.begin(), bson.end()));
  EXPECT_TRUE(contains(error_of([&] { read_instantvnr(path); }), "n_params must be"));
  root = {{"volume", {{"dims", {{"x", 2}, {"y", -1}, {"z", 1}}}}},
          {"parameters", {{"n_params", 1}, {"params_binary", Json::binary(std::vector<uint8_t>(2))}}}};
  bson = Json::to_bson(root);
  write_bytes(path, std::string(bson.begin(), bson.end()));
  EXPECT_TRUE(contains(error_of([&] { read_instantvnr(path); }), "volume.dims.y"));

  // a BSON document without parameters at all
  bson = Json::to_bson(Json{{"hello", 1}});
  write_bytes(path, std::string(bson.begin(), bson.end()));
  EXPECT_TRUE(contains(error_of([&] { read_instantvnr(path); }), "not an instantvnr params file"));

  // not BSON
  write_bytes(path, std::string("\x05\x00\x00\x00garbage", 11));
  std::string msg = error_of([&] { read_instantvnr(path); });
  EXPECT_TRUE(contains(msg, "invalid BSON")) << msg;
  EXPECT_FALSE(contains(msg, "\n"));
}

TEST(InstantVnrFile, FuzzedBsonNeverCrashes) {
  // BSON has no checksum, so a corrupted file may still load; it must never crash or hang.
  TmpDir tmp;
  std::string dir = tmp.str(), path = dir + "/p.json", bad = dir + "/bad.json";
  write_instantvnr(path, make_model(25, 200, {20, 20, 12}));
  const std::string b = read_file(path);
  std::mt19937 rng(777);
  int errors = 0;
  for (int i = 0; i < 200; ++i) {
    std::string c = b;
    size_t pos = rng() % c.size();
    c[pos] = char(uint8_t(c[pos]) ^ uint8_t(1 + rng() % 255));
    if (i % 4 == 0) c.resize(rng() % c.size());
    write_bytes(bad, c);
    try {
      read_model(bad);
    } catch (const Error&) {
      ++errors;
    }
  }
  EXPECT_GT(errors, 0);
}
