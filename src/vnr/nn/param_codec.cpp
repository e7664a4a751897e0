#include "vnr/nn/param_codec.h"
#include <zstd.h>
#include <algorithm>
#include <cmath>
#include <cstring>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/core/half.h"
#include "vnr/core/parallel.h"
#include "vnr/nn/encoding.h"
#include "vnr/nn/grid_encoding.h"
#include "vnr/nn/mlp_layout.h"

namespace vnr {
namespace {

// Zigzag maps small signed indices to small unsigned symbols (0, -1, 1, -2 ... -> 0, 1, 2, 3 ...).
uint32_t zigzag(int32_t q) { return q >= 0 ? uint32_t(q) << 1 : (uint32_t(-q) << 1) - 1; }
int32_t unzigzag(uint32_t s) { return (s & 1) ? -int32_t((s + 1) >> 1) : int32_t(s >> 1); }

int32_t quant_index(uint16_t h, float step) {
  const float v = half_to_float(h);
  if (!std::isfinite(v)) return 0;
  const float q = std::nearbyint(v / step);
  return int32_t(std::clamp(q, -float(kMaxQuantIndex), float(kMaxQuantIndex)));
}

uint16_t dequant(int32_t q, float step) { return float_to_half(float(q) * step); }

bool valid_step(float step) { return std::isfinite(step) && step >= 0; }

// f(i) for every segment i < n, segments claimed by whichever thread is free (they code independently);
// the first segment's error is raised here, after the parallel region (none may leave a worker thread).
template <typename F>
void for_each_segment(size_t n, F&& f) {
  std::vector<std::string> errors(n);
  parallel_for_claimed(int64_t(n), 1, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) {
      try {
        f(size_t(i));
      } catch (const std::exception& x) {
        errors[size_t(i)] = x.what();
      }
    }
  });
  for (const std::string& e : errors)
    if (!e.empty()) fail("{}", e);
}

}  // namespace

std::vector<ParamSegment> param_segments(const ModelConfig& config) {
  std::vector<ParamSegment> segs;
  const MlpLayout mlp = make_mlp_layout(config);
  for (uint32_t k = 0; k < mlp.n_matrices; ++k) segs.push_back({mlp.rows[k] * mlp.cols[k], 0.0f, {}});
  const auto enc = make_encoding(config.encoding);
  if (const GridLayout* g = enc->grid()) {
    for (uint32_t l = 0; l < g->n_levels; ++l) {
      const GridLevel& L = g->levels[l];
      segs.push_back({uint64_t(L.n_entries) * g->n_features, 0.0f, {g->n_features, L.hashed ? 0u : L.res}});
    }
  } else if (enc->n_params() > 0) {
    segs.push_back({enc->n_params(), 0.0f, {}});
  }
  return segs;
}

void quantize_params(std::vector<uint16_t>& params, std::vector<ParamSegment>& segments) {
  if (segments.empty()) return;  // plain fp16 storage
  uint64_t off = 0;
  for (ParamSegment& s : segments) {
    if (!valid_step(s.step)) fail("invalid quantization step {}", s.step);
    if (off + s.count > params.size()) fail("quantization segments cover more than the {} parameters", params.size());
    uint16_t* p = params.data() + off;
    off += s.count;
    if (s.step == 0) continue;
    float max_abs = 0;
    for (uint64_t i = 0; i < s.count; ++i) {
      const float v = half_to_float(p[i]);
      if (std::isfinite(v)) max_abs = std::max(max_abs, std::fabs(v));
    }
    s.step = std::max(s.step, max_abs / float(kMaxQuantIndex));
    if (s.step == 0) s.step = 1;  // an all-zero segment: any step represents it exactly
    for (uint64_t i = 0; i < s.count; ++i) p[i] = dequant(quant_index(p[i], s.step), s.step);
  }
  if (off != params.size()) fail("quantization segments cover {} of {} parameters", off, params.size());
}

namespace {

struct CodedSegment {
  std::string bytes;
  int width = 0;         // zstd: symbol bytes
  bool context = false;  // coded by encode_param_indices instead
  uint32_t crc = 0;      // context: CRC-32 of the indices (int32, little-endian)
};

// One segment's zstd frame. Symbols: zigzagged indices (or the raw fp16 bits when step is 0), one byte
// each when they fit, else a low-byte plane then a high-byte plane (zstd models each plane better apart).
CodedSegment zstd_segment(const std::vector<uint32_t>& sym, int zstd_level) {
  const uint64_t n = sym.size();
  const uint32_t max_sym = n ? *std::max_element(sym.begin(), sym.end()) : 0;
  const int width = max_sym < 256 ? 1 : 2;
  std::vector<uint8_t> planes(n * width);
  for (uint64_t i = 0; i < n; ++i) {
    planes[i] = uint8_t(sym[i]);
    if (width == 2) planes[n + i] = uint8_t(sym[i] >> 8);
  }
  std::string frame(ZSTD_compressBound(planes.size()), '\0');
  const size_t got = ZSTD_compress(frame.data(), frame.size(), planes.data(), planes.size(), zstd_level);
  if (ZSTD_isError(got)) fail("zstd compression failed: {}", ZSTD_getErrorName(got));
  frame.resize(got);
  return {std::move(frame), width, false};
}

// The smaller of the zstd frame and the context-coded stream (quantized segments only).
CodedSegment encode_segment(const uint16_t* p, const ParamSegment& s, int zstd_level) {
  std::vector<uint32_t> sym(s.count);
  if (s.step == 0) {
    for (uint64_t i = 0; i < s.count; ++i) sym[i] = p[i];
    return zstd_segment(sym, zstd_level);
  }
  std::vector<int32_t> q(s.count);
  for (uint64_t i = 0; i < s.count; ++i) {
    q[i] = quant_index(p[i], s.step);
    sym[i] = zigzag(q[i]);
  }
  CodedSegment z = zstd_segment(sym, zstd_level);
  std::vector<uint8_t> ac = encode_param_indices(q.data(), s.count, s.layout);
  if (ac.size() >= z.bytes.size()) return z;
  return {std::string(ac.begin(), ac.end()), 0, true, crc32_of(q.data(), q.size() * sizeof(int32_t))};
}

}  // namespace

std::string encode_params(const std::vector<uint16_t>& params, const std::vector<ParamSegment>& segments,
                          Json& meta, std::string* codec, int zstd_level) {
  std::vector<uint64_t> offsets;
  uint64_t off = 0;
  for (const ParamSegment& s : segments) {
    if (!valid_step(s.step)) fail("invalid quantization step {}", s.step);
    offsets.push_back(off);
    off += s.count;
  }
  if (off != params.size()) fail("quantization segments cover {} of {} parameters", off, params.size());
  // Segments are coded independently, so in parallel (rate control encodes many candidates).
  std::vector<CodedSegment> coded(segments.size());
  for_each_segment(segments.size(), [&](size_t i) { coded[i] = encode_segment(params.data() + offsets[i], segments[i], zstd_level); });
  meta = Json::array();
  std::string block;
  bool any_context = false;
  for (size_t i = 0; i < segments.size(); ++i) {
    block += coded[i].bytes;
    Json m = {{"n", segments[i].count}, {"step", segments[i].step}};
    if (coded[i].context) {
      m["coder"] = "context";
      m["entry"] = segments[i].layout.entry;
      m["res"] = segments[i].layout.res;
      m["crc"] = coded[i].crc;
      any_context = true;
    } else {
      m["width"] = coded[i].width;
    }
    m["bytes"] = uint64_t(coded[i].bytes.size());
    meta.push_back(std::move(m));
  }
  *codec = any_context ? kParamsContextCodec : kParamsZstdCodec;
  return block;
}

namespace {

// A segment's header entry, checked: n, step and bytes, and width (zstd) or entry and res (context).
struct SegmentMeta {
  uint64_t n = 0, bytes = 0, width = 0;
  uint32_t crc = 0;
  float step = 0;
  bool context = false;
  IndexLayout layout;
};

SegmentMeta segment_meta(const std::string& path, const Json& s) {
  auto unsigned_key = [&](const char* k) { return s.contains(k) && s[k].is_number_unsigned(); };
  if (!s.is_object() || !unsigned_key("n") || !unsigned_key("bytes") || !s.contains("step") || !s["step"].is_number())
    fail("'{}' has an invalid header: each parameter segment needs n, step and bytes", path);
  SegmentMeta m;
  m.n = s["n"].get<uint64_t>();
  m.bytes = s["bytes"].get<uint64_t>();
  const double step_d = s["step"].get<double>();
  m.step = float(step_d);
  if (!valid_step(m.step) || double(m.step) != step_d) fail("'{}' is corrupted (quantization step {})", path, step_d);
  m.context = s.contains("coder");
  if (!m.context) {
    if (!unsigned_key("width")) fail("'{}' has an invalid header: a zstd parameter segment needs a width", path);
    m.width = s["width"].get<uint64_t>();
    if (m.width != 1 && m.width != 2) fail("'{}' is corrupted (parameter segment width {})", path, m.width);
    return m;
  }
  if (s["coder"] != "context" || !unsigned_key("entry") || !unsigned_key("res") || !unsigned_key("crc") ||
      s["crc"].get<uint64_t>() > UINT32_MAX)
    fail("'{}' has an invalid header: a parameter segment's coder must be \"context\" with entry, res and crc", path);
  m.crc = uint32_t(s["crc"].get<uint64_t>());
  const uint64_t entry = s["entry"].get<uint64_t>(), res = s["res"].get<uint64_t>();
  if (entry < 1 || entry > 64 || res > UINT32_MAX || m.step == 0)
    fail("'{}' is corrupted (context-coded segment: entry {}, res {}, step {})", path, entry, res, m.step);
  m.layout = {uint32_t(entry), uint32_t(res)};
  return m;
}

// One segment's parameters into p[0, n): raw fp16 bits (step 0) or dequantized indices, from either coder.
void decode_segment(const std::string& path, const SegmentMeta& m, const char* data, uint16_t* p) {
  std::vector<int32_t> q(m.n);
  if (m.context) {
    if (!decode_param_indices(reinterpret_cast<const uint8_t*>(data), m.bytes, m.n, m.layout, q.data()))
      fail("'{}' is corrupted (context-coded parameters are damaged or truncated)", path);
    if (crc32_of(q.data(), q.size() * sizeof(int32_t)) != m.crc)
      fail("'{}' is corrupted (context-coded parameters fail their checksum)", path);
  } else {
    std::vector<uint8_t> planes(m.n * m.width);
    if (ZSTD_getFrameContentSize(data, m.bytes) != planes.size())
      fail("'{}' is corrupted (compressed parameter segment has the wrong size)", path);
    const size_t got = ZSTD_decompress(planes.data(), planes.size(), data, m.bytes);
    if (ZSTD_isError(got) || got != planes.size())
      fail("'{}' is corrupted (compressed parameters: {})", path,
           ZSTD_isError(got) ? ZSTD_getErrorName(got) : "short segment");
    for (uint64_t i = 0; i < m.n; ++i) {
      const uint32_t sym = planes[i] | (m.width == 2 ? uint32_t(planes[m.n + i]) << 8 : 0u);
      if (m.step == 0) p[i] = uint16_t(sym);
      else q[i] = unzigzag(sym);
    }
    if (m.step == 0) return;
  }
  for (uint64_t i = 0; i < m.n; ++i) {
    if (q[i] > kMaxQuantIndex || q[i] < -kMaxQuantIndex) fail("'{}' is corrupted (quantization index {})", path, q[i]);
    p[i] = dequant(q[i], m.step);
  }
}

}  // namespace

std::vector<uint16_t> decode_params(const std::string& path, const char* block, uint64_t block_bytes,
                                    const Json& meta, uint64_t n_params, std::vector<ParamSegment>& segments) {
  if (!meta.is_array()) fail("'{}' has an invalid header: 'params_encoding.segments' must be an array", path);
  using u128 = unsigned __int128;
  u128 total_n = 0, total_bytes = 0;
  std::vector<SegmentMeta> metas;
  for (const Json& s : meta) {
    metas.push_back(segment_meta(path, s));
    total_n += metas.back().n;
    total_bytes += metas.back().bytes;
  }
  if (total_n != n_params)
    fail("'{}' is corrupted (parameter segments hold {} values, n_params is {})", path, uint64_t(total_n), n_params);
  if (total_bytes != block_bytes) fail("'{}' is corrupted (parameter segment sizes do not add up to the block)", path);

  std::vector<uint16_t> params(static_cast<size_t>(n_params));
  std::vector<uint64_t> offsets, positions;
  uint64_t off = 0, pos = 0;
  for (const SegmentMeta& m : metas) {
    offsets.push_back(off);
    positions.push_back(pos);
    off += m.n;
    pos += m.bytes;
  }
  // Segments decode independently, so in parallel (a model loads in about half the time on 2 cores).
  for_each_segment(metas.size(), [&](size_t s) {
    decode_segment(path, metas[s], block + positions[s], params.data() + offsets[s]);
  });
  segments.clear();
  for (const SegmentMeta& m : metas) segments.push_back({m.n, m.step, m.layout});
  return params;
}

void restore_segment_layouts(const Json& config, std::vector<ParamSegment>& segments) {
  std::vector<ParamSegment> want;
  try {
    want = param_segments(ModelConfig::from_json(config));
  } catch (const std::exception&) {
    return;
  }
  if (want.size() != segments.size()) return;
  for (size_t i = 0; i < want.size(); ++i)
    if (want[i].count == segments[i].count) segments[i].layout = want[i].layout;
}

bool macrocells_fit_u8(const std::vector<float>& r) {
  for (size_t i = 0; i + 1 < r.size(); i += 2) {
    if (!std::isfinite(r[i]) || !std::isfinite(r[i + 1])) return false;
    if (r[i] <= r[i + 1] && (r[i] < 0 || r[i + 1] > 1)) return false;
  }
  return true;
}

std::string encode_macrocells_u8(const std::vector<float>& r) {
  const size_t cells = r.size() / 2;
  std::vector<uint8_t> planes(2 * cells);
  for (size_t c = 0; c < cells; ++c) {
    const float lo = r[2 * c], hi = r[2 * c + 1];
    if (lo > hi) {  // empty: decodes to (1, 0), still empty
      planes[c] = 255;
      planes[cells + c] = 0;
      continue;
    }
    // The largest code whose decoded float is <= lo, the smallest whose decoded float is >= hi: exact,
    // so that decoded ranges encode to themselves again.
    int a = int(std::clamp(std::floor(double(lo) * 255.0), 0.0, 255.0));
    if (a < 255 && float(a + 1) / 255.0f <= lo) ++a;
    int b = int(std::clamp(std::ceil(double(hi) * 255.0), 0.0, 255.0));
    if (b > 0 && float(b - 1) / 255.0f >= hi) --b;
    planes[c] = uint8_t(a);
    planes[cells + c] = uint8_t(b);
  }
  std::string frame(ZSTD_compressBound(planes.size()), '\0');
  const size_t n = ZSTD_compress(frame.data(), frame.size(), planes.data(), planes.size(), 19);
  if (ZSTD_isError(n)) fail("zstd compression failed: {}", ZSTD_getErrorName(n));
  frame.resize(n);
  return frame;
}

std::vector<float> decode_macrocells_u8(const std::string& path, const char* block, uint64_t bytes, uint64_t cells) {
  std::vector<uint8_t> planes(static_cast<size_t>(2 * cells));
  if (ZSTD_getFrameContentSize(block, bytes) != planes.size())
    fail("'{}' is corrupted (compressed macro-cells have the wrong size)", path);
  const size_t got = ZSTD_decompress(planes.data(), planes.size(), block, bytes);
  if (ZSTD_isError(got) || got != planes.size()) fail("'{}' is corrupted (compressed macro-cells)", path);
  std::vector<float> r(static_cast<size_t>(2 * cells));
  for (uint64_t c = 0; c < cells; ++c) {
    r[2 * c] = float(planes[c]) / 255.0f;
    r[2 * c + 1] = float(planes[cells + c]) / 255.0f;
  }
  return r;
}

}  // namespace vnr
