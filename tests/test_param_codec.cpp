// .vnr format version 2: compressed (quantized, zstd- or context-coded) parameters and the residual block.
#include <gtest/gtest.h>
#include <cmath>
#include <cstring>
#include <functional>
#include <random>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/core/half.h"
#include "vnr/math.h"
#include "vnr/nn/header_codec.h"
#include "vnr/nn/model_file.h"
#include "vnr/nn/network.h"
#include "vnr/nn/param_codec.h"
#include "test_support.h"

using namespace vnr;
using namespace vnr::test;

namespace {

Json small_config() {
  return Json::parse(R"({
    "loss": {"otype": "L2"},
    "optimizer": {"otype": "Adam", "learning_rate": 1e-2},
    "encoding": {"otype": "HashGrid", "n_levels": 4, "n_features_per_level": 2, "log2_hashmap_size": 10,
                 "base_resolution": 4, "per_level_scale": 2.0},
    "network": {"otype": "FullyFusedMLP", "activation": "ReLU", "n_neurons": 16, "n_hidden_layers": 1,
                "output_activation": "None"}
  })");
}

// A model of `small_config` with trained-looking parameters: Gaussian MLP weights, grid values of a
// few hundredths, and macro-cells.
ModelFile make_model(uint32_t seed, bool macrocells = true) {
  Network net(small_config());
  std::mt19937 rng(seed);
  std::normal_distribution<float> nd(0, 1);
  ModelFile m;
  m.config = small_config();
  m.dims = {20, 17, 9};
  m.source_dtype = DType::UInt8;
  m.lo = 0;
  m.hi = 255;
  m.params.resize(net.n_params());
  for (size_t i = 0; i < m.params.size(); ++i)
    m.params[i] = float_to_half(i < net.mlp().n_params ? 0.3f * nd(rng) : 0.05f * nd(rng));
  if (macrocells) {
    m.macrocell_dims = {2, 2, 1};
    m.macrocell_ranges = {0.f, 1.f, 0.25f, 0.5f, 1.f, -1.f, 0.f, 0.125f};
  }
  m.training = Json{{"steps", 10}};
  return m;
}

std::vector<ParamSegment> segments_with_step(const ModelFile& m, float mlp_step, float grid_step) {
  auto segs = param_segments(ModelConfig::from_json(m.config));
  const uint32_t n_matrices = small_config()["network"]["n_hidden_layers"].get<uint32_t>() + 1;
  for (size_t i = 0; i < segs.size(); ++i) segs[i].step = i < n_matrices ? mlp_step : grid_step;
  return segs;
}

uint32_t version_of(const std::string& bytes) {
  uint32_t v;
  std::memcpy(&v, bytes.data() + 8, 4);
  return v;
}

uint64_t header_length(const std::string& file) {
  uint64_t n;
  std::memcpy(&n, file.data() + 16, 8);
  return n;
}

// Where the first data block starts: format 3 does not pad (docs/MODEL_FORMAT.md 1.6).
uint64_t first_block(const std::string& file) {
  const uint64_t end = 24 + header_length(file);
  return version_of(file) >= 3 ? end : next_multiple(end, 64);
}

// The header JSON of a .vnr file, coded (format 3) or not.
Json header_of(const std::string& file) {
  const std::string stored = file.substr(24, header_length(file));
  return Json::parse(version_of(file) >= 3 ? decompress_vnr_header("<test>", stored, 1 << 20) : stored);
}

// Rewrites a .vnr file's header JSON (blocks re-padded behind it, CRC recomputed): damage that the
// checksum does not catch, as a buggy or hostile writer would produce.
std::string with_header(const std::string& file, const std::function<void(Json&)>& edit) {
  const uint64_t blocks = first_block(file), end = file.size() - 12;
  Json h = header_of(file);
  edit(h);
  std::string header = h.dump(), out = file.substr(0, 16);
  if (version_of(file) >= 3) header = compress_vnr_header(header);
  const uint64_t n = header.size();
  out.append(reinterpret_cast<const char*>(&n), 8);
  out += header;
  if (version_of(file) < 3) out.resize(next_multiple(out.size(), 64), '\0');
  out += file.substr(blocks, end - blocks);
  const uint32_t crc = crc32_of(out.data(), out.size());
  out.append(reinterpret_cast<const char*>(&crc), 4);
  out += file.substr(file.size() - 8);
  return out;
}

}  // namespace

TEST(ParamCodec, SegmentsFollowTheLayout) {
  Network net(small_config());
  auto segs = param_segments(net.config());
  ASSERT_EQ(segs.size(), 2u + 4u);  // two matrices, four levels
  uint64_t total = 0;
  for (auto& s : segs) total += s.count;
  EXPECT_EQ(total, net.n_params());
  EXPECT_EQ(segs[0].count, net.mlp().rows[0] * net.mlp().cols[0]);
  EXPECT_EQ(segs[2].count, uint64_t(net.grid().levels[0].n_entries) * 2);
}

TEST(ParamCodec, QuantizeMatchesAPlainReference) {
  ModelFile m = make_model(1);
  auto segs = segments_with_step(m, 0.01f, 0.002f);
  std::vector<uint16_t> q = m.params;
  quantize_params(q, segs);
  uint64_t off = 0;
  for (const auto& s : segs) {
    for (uint64_t i = off; i < off + s.count; ++i) {
      const double idx = std::clamp(std::nearbyint(double(half_to_float(m.params[i])) / s.step), -1023.0, 1023.0);
      ASSERT_EQ(q[i], float_to_half(float(int(idx)) * s.step)) << i;  // int: -0 is stored as +0
      // half a step, plus fp16 rounding of the dequantized value
      EXPECT_LE(std::fabs(half_to_float(q[i]) - half_to_float(m.params[i])),
                0.5 * s.step + std::fabs(half_to_float(q[i])) * 0x1p-11 + 1e-7);
    }
    off += s.count;
  }
  // Quantizing again is exact: what a file holds survives any number of read/write cycles.
  std::vector<uint16_t> q2 = q;
  quantize_params(q2, segs);
  EXPECT_EQ(q2, q);
  // A step too fine for the index range is raised to max|p| / 1023.
  auto fine = segments_with_step(m, 1e-9f, 1e-9f);
  std::vector<uint16_t> q3 = m.params;
  quantize_params(q3, fine);
  for (const auto& s : fine) EXPECT_GT(s.step, 1e-5f);
}

TEST(ParamCodec, CompressedRoundTripIsExactAndVersion3) {
  TmpDir tmp;
  const std::string a = tmp.str() + "/a.vnr", b = tmp.str() + "/b.vnr";
  ModelFile m = make_model(2);
  m.param_segments = segments_with_step(m, 0.01f, 0.004f);
  quantize_params(m.params, m.param_segments);
  write_vnr(a, m);
  const std::string bytes = read_file(a);
  EXPECT_EQ(version_of(bytes), 3u);
  EXPECT_EQ(vnr_file_bytes(m), bytes.size());
  ModelFile r = read_vnr(a);
  EXPECT_EQ(r.params, m.params);
  ASSERT_EQ(r.param_segments.size(), m.param_segments.size());
  for (size_t i = 0; i < r.param_segments.size(); ++i) {
    EXPECT_EQ(r.param_segments[i].count, m.param_segments[i].count);
    EXPECT_EQ(r.param_segments[i].step, m.param_segments[i].step);
  }
  EXPECT_EQ(r.macrocell_ranges, m.macrocell_ranges);
  EXPECT_EQ(r.config, m.config);
  EXPECT_EQ(r.training, m.training);
  write_vnr(b, r);  // read then write again: the same bytes
  EXPECT_EQ(read_file(b), bytes);
  // A plain copy stays version 1 and is larger (fp16 against a few bits per value).
  ModelFile plain = m;
  plain.param_segments.clear();
  write_vnr(b, plain);
  EXPECT_EQ(version_of(read_file(b)), 1u);
  EXPECT_LT(bytes.size() * 2, read_file(b).size());
  EXPECT_EQ(read_vnr(b).params, m.params);
}

// Format 3 codes the header against a fixed dictionary and leaves the blocks unpadded
// (docs/MODEL_FORMAT.md 1.6); files of format 2 still read.
TEST(ParamCodec, Version3CodesTheHeaderAndVersion2StillReads) {
  // Every file of format 3 depends on these exact bytes.
  EXPECT_EQ(kVnrHeaderDictionary.size(), 8549u);
  EXPECT_EQ(crc32_of(kVnrHeaderDictionary.data(), kVnrHeaderDictionary.size()), 0xe3543dc2u);

  TmpDir tmp;
  const std::string path = tmp.str() + "/a.vnr", bad = tmp.str() + "/bad.vnr";
  ModelFile m = make_model(4);
  m.param_segments = segments_with_step(m, 0.01f, 0.004f);
  quantize_params(m.params, m.param_segments);
  m.residuals_meta = Json{{"codec", "test"}};
  m.residuals_bytes.assign(10, 7);
  write_vnr(path, m);
  const std::string b = read_file(path);
  ASSERT_EQ(version_of(b), 3u);
  const Json h = header_of(b);
  EXPECT_EQ(h["config"], m.config);
  EXPECT_EQ(h["training"], m.training);
  EXPECT_LT(header_length(b) * 3, h.dump().size());  // the dictionary knows the keys and the config
  // No padding: the residual block ends right before the trailer.
  EXPECT_EQ(b.substr(b.size() - 22, 10), std::string(10, '\7'));
  const ModelFile r = read_vnr(path);
  EXPECT_EQ(r.params, m.params);
  EXPECT_EQ(r.residuals_bytes, m.residuals_bytes);

  // A damaged coded header under a valid checksum: one clear line, never a crash.
  std::mt19937 rng(5);
  for (int i = 0; i < 100; ++i) {
    std::string c = b;
    const size_t pos = 24 + rng() % header_length(b);
    c[pos] = char(uint8_t(c[pos]) ^ uint8_t(1 + rng() % 255));
    const uint32_t crc = crc32_of(c.data(), c.size() - 12);
    std::memcpy(c.data() + c.size() - 12, &crc, 4);
    write_bytes(bad, c);
    try {
      read_vnr(bad);
    } catch (const Error& e) {
      EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
    }
  }
  std::string unended = b.substr(0, 24 + header_length(b) / 2);
  write_bytes(bad, unended);
  EXPECT_NE(one_line_error_of([&] { read_vnr(bad); }).find("truncated"), std::string::npos);

  // A compact model written before format 3 (tests/data, format 2, padded, plain header) reads.
  const std::string v2 = read_file(std::string(VNR_TEST_DATA_DIR) + "/compact_quant_zstd.vnr");
  ASSERT_EQ(version_of(v2), 2u);
  const ModelFile old = read_vnr(std::string(VNR_TEST_DATA_DIR) + "/compact_quant_zstd.vnr");
  EXPECT_EQ(Json(old.config), header_of(v2)["config"]);
  EXPECT_FALSE(old.param_segments.empty());
}

TEST(ParamCodec, RawSegmentsKeepEveryBitPattern) {
  TmpDir tmp;
  const std::string path = tmp.str() + "/m.vnr";
  ModelFile m = make_model(3, false);
  m.params[5] = 0x7e00;  // NaN, kept as raw bits in a step-0 segment
  m.param_segments = segments_with_step(m, 0.0f, 0.01f);
  quantize_params(m.params, m.param_segments);
  write_vnr(path, m);
  ModelFile r = read_vnr(path);
  EXPECT_EQ(r.params, m.params);
  EXPECT_EQ(r.params[5], 0x7e00);
}

// Inference on a loaded compressed model equals inference on the dequantized parameters, value for
// value: the loader hands the network exactly the dequantized fp16 values.
TEST(ParamCodec, QuantizedInferenceEqualsDequantizeThenInfer) {
  TmpDir tmp;
  const std::string path = tmp.str() + "/m.vnr";
  ModelFile m = make_model(4, false);
  const auto segs = segments_with_step(m, 0.02f, 0.003f);
  m.param_segments = segs;
  write_vnr(path, m);  // the writer quantizes the unquantized parameters itself

  std::vector<uint16_t> deq = m.params;  // independent dequantization
  uint64_t off = 0;
  for (const auto& s : segs) {
    for (uint64_t i = off; i < off + s.count; ++i)
      deq[i] = float_to_half(float(int(std::nearbyint(half_to_float(m.params[i]) / s.step))) * s.step);
    off += s.count;
  }
  Network reference(small_config()), loaded(small_config());
  reference.set_params_half(deq);
  loaded.set_params_half(read_vnr(path).params);
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> u(0, 1);
  std::vector<float> xyz(3 * 4096);
  for (float& v : xyz) v = u(rng);
  std::vector<float> a(4096), b(4096), c(4096);
  reference.infer(xyz.data(), 4096, a.data());
  loaded.infer(xyz.data(), 4096, b.data());
  EXPECT_EQ(0, std::memcmp(a.data(), b.data(), a.size() * 4));
  Network unquantized(small_config());
  unquantized.set_params_half(m.params);
  unquantized.infer(xyz.data(), 4096, c.data());
  EXPECT_NE(0, std::memcmp(a.data(), c.data(), a.size() * 4));  // quantization did change the model
}

TEST(ResidualBlock, RoundTripsAfterTheMacrocells) {
  TmpDir tmp;
  const std::string path = tmp.str() + "/m.vnr";
  for (bool compressed : {false, true})
    for (bool macrocells : {false, true}) {
      ModelFile m = make_model(5, macrocells);
      if (compressed) m.param_segments = segments_with_step(m, 0.01f, 0.01f);
      quantize_params(m.params, m.param_segments);
      m.residuals_meta = Json{{"codec", "test"}, {"bound", 0.5}};
      for (int i = 0; i < 301; ++i) m.residuals_bytes.push_back(uint8_t(i * 7));
      write_vnr(path, m);
      const std::string bytes = read_file(path);
      EXPECT_EQ(version_of(bytes), 3u);
      // The block is the last before the trailer (format 3: no padding before it).
      const uint64_t start = bytes.size() - 12 - 301;
      EXPECT_EQ(0, std::memcmp(bytes.data() + start, m.residuals_bytes.data(), 301));
      ModelFile r = read_vnr(path);
      EXPECT_EQ(r.residuals_meta, m.residuals_meta);
      EXPECT_EQ(r.residuals_bytes, m.residuals_bytes);
      EXPECT_EQ(r.params, m.params);
      EXPECT_EQ(r.macrocell_ranges, m.macrocell_ranges);
    }
  ModelFile m = make_model(5);
  m.residuals_bytes = {1, 2};
  EXPECT_TRUE(error_of([&] { write_vnr(path, m); }).find("without their description") != std::string::npos);
}

TEST(ParamCodec, DamagedFilesAreClearErrors) {
  TmpDir tmp;
  const std::string path = tmp.str() + "/m.vnr", bad = tmp.str() + "/bad.vnr";
  ModelFile m = make_model(6);
  m.param_segments = segments_with_step(m, 0.01f, 0.004f);
  m.residuals_meta = Json::object();
  m.residuals_bytes.assign(100, 3);
  write_vnr(path, m);
  const std::string b = read_file(path);
  std::mt19937 rng(77);
  for (int i = 0; i < 200; ++i) {  // single-byte damage: the checksum (or an earlier check) catches it
    std::string c = b;
    const size_t pos = rng() % c.size();
    c[pos] = char(uint8_t(c[pos]) ^ uint8_t(1 + rng() % 255));
    write_bytes(bad, c);
    EXPECT_THROW(read_model(bad), Error) << pos;
  }
  for (int i = 0; i < 50; ++i) {
    write_bytes(bad, b.substr(0, rng() % b.size()));
    EXPECT_THROW(read_model(bad), Error);
  }
  // A consistent checksum over inconsistent content: each is one clear line.
  auto expect_error = [&](const std::function<void(Json&)>& edit, const std::string& needle) {
    write_bytes(bad, with_header(b, edit));
    const std::string msg = one_line_error_of([&] { read_vnr(bad); });
    EXPECT_NE(msg.find(needle), std::string::npos) << msg;
  };
  write_bytes(bad, with_header(b, [](Json&) {}));
  EXPECT_EQ(read_vnr(bad).params, read_vnr(path).params);  // the helper itself keeps the file valid
  expect_error([](Json& h) { h["params_encoding"]["codec"] = "lzma"; }, "unsupported params_encoding");
  expect_error([](Json& h) { h["params_encoding"]["segments"][0]["n"] = 3; }, "n_params is");
  expect_error([](Json& h) { h["params_encoding"]["segments"][0]["bytes"] = 3; }, "do not add up");
  expect_error([](Json& h) { h["params_encoding"]["segments"][0]["width"] = 3; }, "width 3");  // zstd (step 0.01)
  expect_error([](Json& h) { h["params_encoding"]["segments"][1]["step"] = -1; }, "quantization step");
  expect_error([](Json& h) { h["params_encoding"]["segments"][1].erase("step"); }, "needs n, step");
  expect_error([](Json& h) { h["params_encoding"]["bytes"] = 1u << 30; }, "header describes");
  expect_error([](Json& h) { h["residuals_bytes"] = 99; }, "header describes");
  expect_error([](Json& h) { h["residuals"] = 5; }, "'residuals' must be an object");
  expect_error([](Json& h) {  // sizes swapped between two segments: zstd frames no longer line up
    auto& s = h["params_encoding"]["segments"];
    std::swap(s[0]["bytes"], s[2]["bytes"]);
  }, "corrupted");
  // Damage inside a compressed frame under a valid checksum never crashes.
  const uint64_t block = first_block(b);
  for (int i = 0; i < 100; ++i) {
    std::string c = b;
    const size_t pos = block + rng() % 200;
    c[pos] = char(uint8_t(c[pos]) ^ uint8_t(1 + rng() % 255));
    write_bytes(bad, with_header(c, [](Json&) {}));
    try {
      read_vnr(bad);
    } catch (const Error&) {
    }
  }
}

// Compact macro-cells: 8 bits per bound, widened outwards (a decoded range contains the stored one),
// empty cells stay empty; ranges outside [0, 1] keep float32.
TEST(CompactMacrocells, WidenOutwardsAndKeepEmptyCells) {
  TmpDir tmp;
  const std::string path = tmp.str() + "/m.vnr";
  ModelFile m = make_model(8);
  m.macrocell_dims = {3, 2, 2};
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0, 1);
  m.macrocell_ranges.clear();
  for (int c = 0; c < 12; ++c) {
    const float a = u(rng), b = u(rng);
    m.macrocell_ranges.push_back(std::min(a, b));
    m.macrocell_ranges.push_back(std::max(a, b));
  }
  m.macrocell_ranges[2] = m.macrocell_ranges[3] = 0.5f;  // a single value
  m.macrocell_ranges[4] = 1.0f, m.macrocell_ranges[5] = -1.0f;  // empty
  m.macrocell_ranges[6] = 0.0f, m.macrocell_ranges[7] = 1.0f;
  m.compact_macrocells = true;
  write_vnr(path, m);
  EXPECT_EQ(version_of(read_file(path)), 3u);
  ModelFile r = read_vnr(path);
  EXPECT_TRUE(r.compact_macrocells);
  ASSERT_EQ(r.macrocell_ranges.size(), m.macrocell_ranges.size());
  for (size_t c = 0; c < 12; ++c) {
    const float lo = m.macrocell_ranges[2 * c], hi = m.macrocell_ranges[2 * c + 1];
    const float dlo = r.macrocell_ranges[2 * c], dhi = r.macrocell_ranges[2 * c + 1];
    if (lo > hi) {
      EXPECT_GT(dlo, dhi) << c;
      continue;
    }
    EXPECT_LE(dlo, lo) << c;
    EXPECT_GE(dhi, hi) << c;
    EXPECT_LE(lo - dlo, 1.0f / 255 + 1e-7f) << c;
    EXPECT_LE(dhi - hi, 1.0f / 255 + 1e-7f) << c;
  }
  EXPECT_EQ(r.macrocell_ranges[6], 0.0f);
  EXPECT_EQ(r.macrocell_ranges[7], 1.0f);
  write_vnr(tmp.str() + "/b.vnr", r);  // stable once stored
  EXPECT_EQ(read_file(tmp.str() + "/b.vnr"), read_file(path));
  // Outside [0, 1]: float32 as before, exact.
  m.macrocell_ranges[1] = 1.5f;
  write_vnr(path, m);
  EXPECT_EQ(version_of(read_file(path)), 1u);
  EXPECT_EQ(read_vnr(path).macrocell_ranges, m.macrocell_ranges);
}

// The context coder alone, on adversarial inputs: every layout it conditions on, and streams that are
// cut short are refused, never read past their end.
TEST(ParamContextCoder, RoundTripsAdversarialInputsExactly) {
  std::mt19937 rng(5);
  std::vector<std::vector<int32_t>> inputs;
  inputs.push_back(std::vector<int32_t>(5000, 0));  // all zeros
  std::vector<int32_t> distinct(2 * kMaxQuantIndex + 1);
  for (size_t i = 0; i < distinct.size(); ++i) distinct[i] = int32_t(i) - kMaxQuantIndex;
  std::shuffle(distinct.begin(), distinct.end(), rng);
  inputs.push_back(distinct);  // all distinct
  std::vector<int32_t> extreme(4096);
  for (size_t i = 0; i < extreme.size(); ++i) extreme[i] = (i % 3 == 0 ? -1 : 1) * kMaxQuantIndex;
  inputs.push_back(extreme);  // maximum range, alternating signs
  std::vector<int32_t> wide(3000);
  for (auto& v : wide) v = int32_t(rng() % 2000001) - 1000000;  // far beyond the unary part
  inputs.push_back(wide);
  std::vector<int32_t> sparse(8 * 8 * 8 * 4);
  for (auto& v : sparse) v = rng() % 7 == 0 ? int32_t(rng() % 9) - 4 : 0;
  inputs.push_back(sparse);
  inputs.push_back({});
  inputs.push_back({-1});
  for (const IndexLayout layout : {IndexLayout{1, 0}, IndexLayout{2, 0}, IndexLayout{4, 8}, IndexLayout{8, 3}}) {
    for (const auto& q : inputs) {
      const std::vector<uint8_t> bytes = encode_param_indices(q.data(), q.size(), layout);
      std::vector<int32_t> back(q.size(), 77);
      ASSERT_TRUE(decode_param_indices(bytes.data(), bytes.size(), q.size(), layout, back.data()));
      EXPECT_EQ(back, q) << "entry " << layout.entry << " res " << layout.res << " n " << q.size();
      if (q.size() >= 2048)
        EXPECT_FALSE(decode_param_indices(bytes.data(), bytes.size() / 2, q.size(), layout, back.data()));
    }
  }
  // All zeros cost next to nothing; the extremes cost about their 11 bits.
  EXPECT_LT(encode_param_indices(inputs[0].data(), 5000, {}).size(), 40u);
  EXPECT_LT(encode_param_indices(distinct.data(), distinct.size(), {}).size(), distinct.size() * 13 / 8);
}

// A grid level whose entries are mostly zero and smooth where not (what training leaves of a hashed
// level) is context coded, smaller than zstd; the file says so and round-trips exactly, and writing
// what was read gives the same bytes. Raw (step 0) segments keep zstd.
TEST(ParamCodec, ContextCodedSegmentsRoundTrip) {
  TmpDir tmp;
  const std::string a = tmp.str() + "/a.vnr", b = tmp.str() + "/b.vnr";
  ModelFile m = make_model(9);
  m.param_segments = segments_with_step(m, 0.0f, 0.004f);
  const uint64_t n_mlp = m.param_segments[0].count + m.param_segments[1].count;
  std::mt19937 rng(9);
  std::normal_distribution<float> nd(0, 1);
  for (size_t i = n_mlp; i < m.params.size(); ++i) {
    const bool touched = (i / 2) % 16 < 3;  // runs of used entries, both features alike
    m.params[i] = float_to_half(touched ? 0.02f * (1 + nd(rng) * 0.2f) : 0.0f);
  }
  quantize_params(m.params, m.param_segments);
  write_vnr(a, m);
  const std::string bytes = read_file(a);
  const Json h = header_of(bytes);
  EXPECT_EQ(h["params_encoding"]["codec"], kParamsContextCodec);
  const Json& segs = h["params_encoding"]["segments"];
  EXPECT_FALSE(segs[0].contains("coder"));
  EXPECT_EQ(segs[2]["coder"], "context");
  EXPECT_EQ(segs[2]["entry"], 2);
  EXPECT_EQ(segs[2]["res"], 4);  // level 0: 4^3 vertices, dense
  ModelFile r = read_vnr(a);
  EXPECT_EQ(r.params, m.params);
  EXPECT_EQ(r.param_segments[2].layout.res, 4u);
  write_vnr(b, r);
  EXPECT_EQ(read_file(b), bytes);
  // A context-coded segment's header is checked like a zstd one's.
  auto expect_error = [&](const std::function<void(Json&)>& edit, const std::string& needle) {
    write_bytes(b, with_header(bytes, edit));
    const std::string msg = one_line_error_of([&] { read_vnr(b); });
    EXPECT_NE(msg.find(needle), std::string::npos) << msg;
  };
  expect_error([](Json& h) { h["params_encoding"]["segments"][2]["coder"] = "lzma"; }, "coder must be");
  expect_error([](Json& h) { h["params_encoding"]["segments"][2]["entry"] = 0; }, "context-coded segment");
  expect_error([](Json& h) { h["params_encoding"]["segments"][2].erase("res"); }, "coder must be");
  expect_error([](Json& h) {  // a stream cut short under a consistent header
    auto& s = h["params_encoding"]["segments"];
    s[2]["bytes"] = s[2]["bytes"].get<uint64_t>() - 2;
    s[3]["bytes"] = s[3]["bytes"].get<uint64_t>() + 2;
  }, "corrupted");
}
