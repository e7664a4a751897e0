#include "vnr/nn/param_codec.h"
#include <zstd.h>
#include <algorithm>
#include <cmath>
#include <cstring>
#include "vnr/core/error.h"
#include "vnr/core/half.h"
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

}  // namespace

std::string encode_segment(const uint16_t* p, const ParamSegment& s, int zstd_level, int* width_out);

std::vector<ParamSegment> param_segments(const ModelConfig& config) {
  std::vector<ParamSegment> segs;
  const MlpLayout mlp = make_mlp_layout(config);
  for (uint32_t k = 0; k < mlp.n_matrices; ++k) segs.push_back({mlp.rows[k] * mlp.cols[k], 0.0f});
  const auto enc = make_encoding(config.encoding);
  if (const GridLayout* g = enc->grid()) {
    for (uint32_t l = 0; l < g->n_levels; ++l)
      segs.push_back({uint64_t(g->levels[l].n_entries) * g->n_features, 0.0f});
  } else if (enc->n_params() > 0) {
    segs.push_back({enc->n_params(), 0.0f});
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

// One segment's zstd frame. Symbols: zigzagged indices (or the raw fp16 bits when step is 0), one byte
// each when they fit, else a low-byte plane then a high-byte plane (zstd models each plane better apart).
std::string encode_segment(const uint16_t* p, const ParamSegment& s, int zstd_level, int* width_out) {
  std::vector<uint16_t> sym(s.count);
  uint32_t max_sym = 0;
  for (uint64_t i = 0; i < s.count; ++i) {
    sym[i] = s.step == 0 ? p[i] : uint16_t(zigzag(quant_index(p[i], s.step)));
    max_sym = std::max<uint32_t>(max_sym, sym[i]);
  }
  const int width = max_sym < 256 ? 1 : 2;
  std::vector<uint8_t> planes(s.count * width);
  for (uint64_t i = 0; i < s.count; ++i) {
    planes[i] = uint8_t(sym[i]);
    if (width == 2) planes[s.count + i] = uint8_t(sym[i] >> 8);
  }
  std::string frame(ZSTD_compressBound(planes.size()), '\0');
  const size_t n = ZSTD_compress(frame.data(), frame.size(), planes.data(), planes.size(), zstd_level);
  if (ZSTD_isError(n)) fail("zstd compression failed: {}", ZSTD_getErrorName(n));
  frame.resize(n);
  *width_out = width;
  return frame;
}

std::string encode_params(const std::vector<uint16_t>& params, const std::vector<ParamSegment>& segments,
                          Json& meta, int zstd_level) {
  std::vector<uint64_t> offsets;
  uint64_t off = 0;
  for (const ParamSegment& s : segments) {
    if (!valid_step(s.step)) fail("invalid quantization step {}", s.step);
    offsets.push_back(off);
    off += s.count;
  }
  if (off != params.size()) fail("quantization segments cover {} of {} parameters", off, params.size());
  // Segments are coded independently, so in parallel (rate control encodes many candidates).
  std::vector<std::string> frames(segments.size());
  std::vector<int> widths(segments.size());
  std::vector<std::string> errors(segments.size());
#pragma omp parallel for schedule(dynamic)
  for (int64_t i = 0; i < int64_t(segments.size()); ++i) {
    try {
      frames[i] = encode_segment(params.data() + offsets[i], segments[i], zstd_level, &widths[i]);
    } catch (const std::exception& e) {
      errors[i] = e.what();
    }
  }
  meta = Json::array();
  std::string block;
  for (size_t i = 0; i < segments.size(); ++i) {
    if (!errors[i].empty()) fail("{}", errors[i]);
    block += frames[i];
    meta.push_back({{"n", segments[i].count}, {"step", segments[i].step}, {"width", widths[i]},
                    {"bytes", uint64_t(frames[i].size())}});
  }
  return block;
}

std::vector<uint16_t> decode_params(const std::string& path, const char* block, uint64_t block_bytes,
                                    const Json& meta, uint64_t n_params, std::vector<ParamSegment>& segments) {
  if (!meta.is_array()) fail("'{}' has an invalid header: 'params_encoding.segments' must be an array", path);
  using u128 = unsigned __int128;
  u128 total_n = 0, total_bytes = 0;
  for (const Json& s : meta) {
    const auto* n = s.is_object() && s.contains("n") ? &s["n"] : nullptr;
    const auto* b = s.is_object() && s.contains("bytes") ? &s["bytes"] : nullptr;
    if (!n || !b || !n->is_number_unsigned() || !b->is_number_unsigned() || !s.contains("step") ||
        !s["step"].is_number() || !s.contains("width") || !s["width"].is_number_unsigned())
      fail("'{}' has an invalid header: each parameter segment needs n, step, width and bytes", path);
    total_n += n->get<uint64_t>();
    total_bytes += b->get<uint64_t>();
  }
  if (total_n != n_params)
    fail("'{}' is corrupted (parameter segments hold {} values, n_params is {})", path, uint64_t(total_n), n_params);
  if (total_bytes != block_bytes) fail("'{}' is corrupted (parameter segment sizes do not add up to the block)", path);

  std::vector<uint16_t> params(static_cast<size_t>(n_params));
  segments.clear();
  uint64_t off = 0, pos = 0;
  std::vector<uint8_t> planes;
  for (const Json& s : meta) {
    const uint64_t n = s["n"].get<uint64_t>(), bytes = s["bytes"].get<uint64_t>();
    const uint64_t width = s["width"].get<uint64_t>();
    const double step_d = s["step"].get<double>();
    const float step = float(step_d);
    if (width != 1 && width != 2) fail("'{}' is corrupted (parameter segment width {})", path, width);
    if (!valid_step(step) || double(step) != step_d) fail("'{}' is corrupted (quantization step {})", path, step_d);
    planes.assign(n * width, 0);
    const unsigned long long content = ZSTD_getFrameContentSize(block + pos, bytes);
    if (content != n * width) fail("'{}' is corrupted (compressed parameter segment has the wrong size)", path);
    const size_t got = ZSTD_decompress(planes.data(), planes.size(), block + pos, bytes);
    if (ZSTD_isError(got) || got != planes.size())
      fail("'{}' is corrupted (compressed parameters: {})", path,
           ZSTD_isError(got) ? ZSTD_getErrorName(got) : "short segment");
    for (uint64_t i = 0; i < n; ++i) {
      const uint32_t sym = planes[i] | (width == 2 ? uint32_t(planes[n + i]) << 8 : 0u);
      if (step == 0) {
        params[off + i] = uint16_t(sym);
        continue;
      }
      const int32_t q = unzigzag(sym);
      if (q > kMaxQuantIndex || q < -kMaxQuantIndex) fail("'{}' is corrupted (quantization index {})", path, q);
      params[off + i] = dequant(q, step);
    }
    segments.push_back({n, step});
    off += n;
    pos += bytes;
  }
  return params;
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
