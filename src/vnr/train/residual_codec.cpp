// The residual block's entropy coding (residuals.h): prediction, zig-zag bytes with an escape stream,
// zstd. Decoding checks every count against the description, so a damaged block is one clear error.
#include <zstd.h>
#include <algorithm>
#include <cstring>
#include <memory>
#include "vnr/error.h"
#include "vnr/core/parallel.h"
#include "vnr/train/residual_context_coder.h"
#include "vnr/train/residuals.h"
#include "vnr/volume/wavelet.h"
#include <zlib.h>

namespace vnr {

namespace {

constexpr int kZstdLevel = 19;
// A budget search's sizes (residuals_for_budget): ~40x faster than level 19, ~10 % larger, in proportion.
constexpr int kZstdSearchLevel = 9;
constexpr uint8_t kEscape = 255;

// 3-D Lorenzo prediction of voxel (x, y, z) from the seven neighbours coded before it (zero outside).
int64_t lorenzo(const int32_t* q, Int3 d, int64_t x, int64_t y, int64_t z) {
  const int64_t sx = 1, sy = d.x, sz = d.x * d.y, i = x + sy * y + sz * z;
  auto at = [&](bool ok, int64_t off) -> int64_t { return ok ? q[i - off] : 0; };
  const bool bx = x > 0, by = y > 0, bz = z > 0;
  return at(bx, sx) + at(by, sy) + at(bz, sz) - at(bx && by, sx + sy) - at(bx && bz, sx + sz) -
         at(by && bz, sy + sz) + at(bx && by && bz, sx + sy + sz);
}

uint32_t zigzag(int64_t v) { return uint32_t((uint64_t(v) << 1) ^ uint64_t(v >> 63)); }
int64_t unzigzag(uint32_t u) { return int64_t(u >> 1) ^ -int64_t(u & 1); }

// Symbols of the values (q, or its Lorenzo differences), one byte per voxel, followed by the escaped
// values, 4 bytes little-endian each.
std::vector<uint8_t> byte_layout(const std::vector<int32_t>& values, uint64_t* escapes) {
  const int64_t n = int64_t(values.size());
  std::vector<uint32_t> z(static_cast<size_t>(n));
  parallel_for_range(n, int64_t(1) << 16, [&](int64_t b, int64_t e) {
    for (int64_t v = b; v < e; ++v) z[size_t(v)] = zigzag(values[size_t(v)]);
  });
  std::vector<uint8_t> out(static_cast<size_t>(n));
  *escapes = 0;
  for (int64_t v = 0; v < n; ++v) {
    const uint32_t u = z[size_t(v)];
    out[size_t(v)] = u < kEscape ? uint8_t(u) : kEscape;
    if (u >= kEscape) {
      ++*escapes;
      for (int b = 0; b < 4; ++b) out.push_back(uint8_t(u >> (8 * b)));
    }
  }
  return out;
}

// CRC-32 of the values' bytes: the arithmetic-coded stream has no checksum of its own.
uint64_t values_crc(const std::vector<int32_t>& q) {
  uLong crc = crc32(0L, Z_NULL, 0);
  const auto* p = reinterpret_cast<const Bytef*>(q.data());
  for (size_t done = 0, total = q.size() * sizeof(int32_t); done < total;) {
    const size_t n = std::min<size_t>(total - done, 1u << 30);
    crc = crc32(crc, p + done, uInt(n));
    done += n;
  }
  return uint64_t(crc);
}

// q minus its Lorenzo prediction at every voxel (|q| < 2^27 keeps the differences inside int32).
std::vector<int32_t> lorenzo_differences(const Residuals& r) {
  const Int3 d = r.dims;
  std::vector<int32_t> out(r.q.size());
  parallel_for(d.z, [&](int64_t k) {
    for (int64_t j = 0; j < d.y; ++j)
      for (int64_t i = 0; i < d.x; ++i) {
        const int64_t v = i + d.x * (j + d.y * k);
        out[size_t(v)] = int32_t(int64_t(r.q[size_t(v)]) - lorenzo(r.q.data(), d, i, j, k));
      }
  });
  return out;
}

std::vector<uint8_t> zstd_compress(const std::vector<uint8_t>& raw, int level) {
  std::vector<uint8_t> out(ZSTD_compressBound(raw.size()));
  // The frame carries a checksum of its content: a damaged block fails to decode instead of decoding wrong.
  std::unique_ptr<ZSTD_CCtx, size_t (*)(ZSTD_CCtx*)> cctx(ZSTD_createCCtx(), ZSTD_freeCCtx);
  ZSTD_CCtx_setParameter(cctx.get(), ZSTD_c_compressionLevel, level);
  ZSTD_CCtx_setParameter(cctx.get(), ZSTD_c_checksumFlag, 1);
  const size_t got = ZSTD_compress2(cctx.get(), out.data(), out.size(), raw.data(), raw.size());
  if (ZSTD_isError(got)) fail("zstd compression of the residuals failed: {}", ZSTD_getErrorName(got));
  out.resize(got);
  return out;
}

// What predicts a voxel: the network (none), the network and Lorenzo over its residuals (lorenzo), nothing
// (values: absolute residuals), or Lorenzo over the quantised values (values-lorenzo). vnr before the
// absolute residuals rejects the last two as a coding it does not know.
const char* predictor_name(const Residuals& r, bool lorenzo) {
  if (r.absolute) return lorenzo ? "values-lorenzo" : "values";
  return lorenzo ? "lorenzo" : "none";
}
// Wavelet coefficients: the context coder alone, in flagged blocks, its contexts also seeing each
// coefficient's parent (neighbours in a subband are alike, as residuals are, and large where their
// parent is; Lorenzo across a subband's coefficients predicts nothing).
EncodedResiduals encode_wavelet(const Residuals& r, const std::string& only) {
  const std::string name = residual_coding_name("wavelet", predictor_name(r, false));
  if (!only.empty() && only != name) fail("unknown residual coding '{}' for wavelet residuals", only);
  EncodedResiduals enc;
  enc.bytes = context_encode(r.q.data(), r.dims, /*wavelet=*/true);
  Json outliers;
  if (!r.outliers.empty()) {  // their stream after the coefficients'
    const std::vector<uint8_t> o = context_encode(r.outliers.data(), r.dims);
    enc.bytes.insert(enc.bytes.end(), o.begin(), o.end());
    outliers = {{"step", r.outlier_step},
                {"bytes", o.size()},
                {"count", int64_t(r.outliers.size()) - std::count(r.outliers.begin(), r.outliers.end(), 0)},
                {"crc32", values_crc(r.outliers)}};
  }
  enc.meta = {{"codec", "context"},
              {"layout", "wavelet-cdf97"},
              {"levels", r.wavelet_levels},
              {"predictor", predictor_name(r, false)},
              {"dims", {r.dims.x, r.dims.y, r.dims.z}},
              {"bound", r.bound},
              {"step", r.step},
              {"nonzero", r.nonzero()},
              {"crc32", values_crc(r.q)},
              {"candidate_bytes", {{name, enc.bytes.size()}}}};
  if (!outliers.is_null()) enc.meta["outliers"] = outliers;
  if (!r.wavelet_offsets.empty()) enc.meta["offsets"] = r.wavelet_offsets;
  return enc;
}
}  // namespace

std::string residual_coding_name(const std::string& codec, const std::string& predictor) {
  return codec + "-" + predictor;
}

EncodedResiduals encode_residuals(const Residuals& r, const std::string& only, bool search) {
  if (r.q.size() != r.dims.count()) fail("residual field of {} values for {} voxels", r.q.size(), r.dims.count());
  if (r.wavelet()) return encode_wavelet(r, only);
  // The candidates (zstd, then the context coder, each without and with Lorenzo), coded concurrently:
  // each coder is serial (zstd at level 19 takes seconds on a large volume), and the smallest is chosen
  // in this order afterwards, so the bytes do not depend on the thread count.
  struct Candidate {
    bool context, predict;
    std::vector<uint8_t> bytes;
    uint64_t escapes = 0, raw_bytes = 0;
  };
  std::vector<Candidate> candidates;
  for (bool context : {false, true})
    for (bool predict : {false, true})
      if (only.empty() || only == residual_coding_name(context ? "context" : "zstd", predictor_name(r, predict)))
        candidates.push_back({context, predict, {}});
  if (candidates.empty()) fail("unknown residual coding '{}'", only);
  // The inputs, each built in parallel: the Lorenzo differences once, for both coders that predict.
  std::vector<int32_t> differences;
  for (const Candidate& c : candidates)
    if (c.predict && differences.empty()) differences = lorenzo_differences(r);
  std::vector<std::vector<uint8_t>> raw(candidates.size());
  for (size_t i = 0; i < candidates.size(); ++i) {
    Candidate& c = candidates[i];
    if (!c.context) raw[i] = byte_layout(c.predict ? differences : r.q, &c.escapes), c.raw_bytes = raw[i].size();
  }
  parallel_for_claimed(int64_t(candidates.size()), 1, [&](int64_t i0, int64_t i1) {
    for (int64_t i = i0; i < i1; ++i) {
      Candidate& c = candidates[size_t(i)];
      if (!c.context) c.bytes = zstd_compress(raw[size_t(i)], search ? kZstdSearchLevel : kZstdLevel);
      else c.bytes = context_encode(c.predict ? differences.data() : r.q.data(), r.dims);
    }
  });
  EncodedResiduals best;
  Json sizes = Json::object();  // every candidate's size, kept in the description for the record
  Candidate* chosen = nullptr;
  for (Candidate& c : candidates) {
    sizes[residual_coding_name(c.context ? "context" : "zstd", predictor_name(r, c.predict))] = c.bytes.size();
    if (!chosen || c.bytes.size() < chosen->bytes.size()) chosen = &c;
  }
  best.meta = {{"codec", chosen->context ? "context" : "zstd"},
               {"layout", chosen->context ? "binary-ac" : "zigzag-bytes"},
               {"predictor", predictor_name(r, chosen->predict)},
               {"dims", {r.dims.x, r.dims.y, r.dims.z}},
               {"bound", r.bound},
               {"step", r.step},
               {"nonzero", r.nonzero()}};
  if (chosen->context) best.meta["crc32"] = values_crc(r.q);
  else best.meta["escapes"] = chosen->escapes, best.meta["raw_bytes"] = chosen->raw_bytes;
  best.meta["candidate_bytes"] = sizes;
  best.bytes = std::move(chosen->bytes);
  return best;
}

namespace {

template <typename T>
T meta_get(const Json& meta, const char* key, const std::string& what) {
  if (!meta.is_object() || !meta.contains(key)) fail("{}: the residual block's description lacks \"{}\"", what, key);
  try {
    return meta.at(key).get<T>();
  } catch (const std::exception&) {
    fail("{}: the residual block's \"{}\" has the wrong type", what, key);
  }
}

}  // namespace

Residuals decode_residuals(const Json& meta, const std::vector<uint8_t>& bytes, Int3 dims, const std::string& what) {
  const auto codec = meta_get<std::string>(meta, "codec", what), layout = meta_get<std::string>(meta, "layout", what);
  const auto predictor = meta_get<std::string>(meta, "predictor", what);
  const bool known = predictor == "none" || predictor == "lorenzo" || predictor == "values" || predictor == "values-lorenzo";
  const bool wavelet = codec == "context" && layout == "wavelet-cdf97" && (predictor == "none" || predictor == "values");
  const bool context = (codec == "context" && layout == "binary-ac" && known) || wavelet;
  if (!context && (codec != "zstd" || layout != "zigzag-bytes" || !known))
    fail("{}: unknown residual coding {}/{}/{} (written by a newer vnr?)", what, codec, layout, predictor);
  const bool lorenzo_coded = predictor == "lorenzo" || predictor == "values-lorenzo";
  const auto md = meta_get<std::vector<int64_t>>(meta, "dims", what);
  if (md.size() != 3 || !(Int3{md[0], md[1], md[2]} == dims))
    fail("{}: the residual block does not match the model's dims", what);
  Residuals r;
  r.dims = dims;
  r.absolute = predictor == "values" || predictor == "values-lorenzo";
  r.bound = meta_get<double>(meta, "bound", what);
  r.step = meta_get<double>(meta, "step", what);
  // A wavelet's step is in coefficients: its bound is measured or kept by outliers, not half the step.
  if (!(r.bound > 0) || !(r.step > 0) || (!wavelet && !(r.step <= 2 * r.bound)) || !std::isfinite(r.bound))
    fail("{}: invalid residual bound {} / step {}", what, r.bound, r.step);
  const int64_t n = dims.count();
  if (context) {
    const auto crc = meta_get<uint64_t>(meta, "crc32", what);
    r.q.resize(size_t(n));
    size_t coded = bytes.size();  // the coefficients' stream; the outliers' follows it
    if (wavelet && meta.contains("outliers")) {
      const Json& o = meta["outliers"];
      const auto o_bytes = meta_get<uint64_t>(o, "bytes", what), o_crc = meta_get<uint64_t>(o, "crc32", what);
      r.outlier_step = meta_get<double>(o, "step", what);
      if (o_bytes > bytes.size()) fail("{}: the residual block is corrupted (outliers past its end)", what);
      if (!(r.outlier_step > 0) || !(r.outlier_step <= 2 * r.bound))
        fail("{}: invalid outlier step {} for the bound {}", what, r.outlier_step, r.bound);
      coded = bytes.size() - o_bytes;
      r.outliers.resize(size_t(n));
      context_decode(bytes.data() + coded, o_bytes, dims, r.outliers.data(), what);
      if (values_crc(r.outliers) != o_crc) fail("{}: the residual block is corrupted (outliers' CRC mismatch)", what);
    }
    context_decode(bytes.data(), coded, dims, r.q.data(), what, wavelet);
    if (lorenzo_coded) {  // differences back to values, in coding order
      int64_t v = 0;
      for (int64_t k = 0; k < dims.z; ++k)
        for (int64_t j = 0; j < dims.y; ++j)
          for (int64_t i = 0; i < dims.x; ++i, ++v) {
            const int64_t q = int64_t(r.q[size_t(v)]) + lorenzo(r.q.data(), dims, i, j, k);
            if (q < INT32_MIN || q > INT32_MAX) fail("{}: the residual block is corrupted (value out of range)", what);
            r.q[size_t(v)] = int32_t(q);
          }
    }
    if (values_crc(r.q) != crc) fail("{}: the residual block is corrupted (CRC mismatch)", what);
    if (wavelet) {
      r.wavelet_levels = meta_get<int>(meta, "levels", what);
      if (r.wavelet_levels < 1 || r.wavelet_levels > wavelet_levels(dims))
        fail("{}: the residual block's wavelet levels ({}) do not fit its dims", what, r.wavelet_levels);
      if (meta.contains("offsets")) {  // absent before vnr rebuilt coefficients at their bins' means
        r.wavelet_offsets = meta_get<std::vector<double>>(meta, "offsets", what);
        if (r.wavelet_offsets.size() != size_t(r.wavelet_levels) + 1 ||
            !std::all_of(r.wavelet_offsets.begin(), r.wavelet_offsets.end(), [](double o) { return o >= -1 && o <= 1; }))
          fail("{}: the residual block's reconstruction offsets are invalid", what);
      }
      invert_wavelet_residuals(r);
    }
    return r;
  }
  const auto escapes = meta_get<uint64_t>(meta, "escapes", what), raw_bytes = meta_get<uint64_t>(meta, "raw_bytes", what);
  if (escapes > uint64_t(n) || raw_bytes != uint64_t(n) + 4 * escapes)
    fail("{}: the residual block's sizes are inconsistent", what);
  const unsigned long long content = ZSTD_getFrameContentSize(bytes.data(), bytes.size());
  if (content != raw_bytes) fail("{}: the residual block is corrupted (not a zstd frame of {} bytes)", what, raw_bytes);
  std::vector<uint8_t> raw(raw_bytes);
  const size_t got = ZSTD_decompress(raw.data(), raw.size(), bytes.data(), bytes.size());
  if (ZSTD_isError(got) || got != raw_bytes)
    fail("{}: the residual block is corrupted ({})", what, ZSTD_isError(got) ? ZSTD_getErrorName(got) : "short");
  if (uint64_t(std::count(raw.begin(), raw.begin() + n, kEscape)) != escapes)
    fail("{}: the residual block is corrupted (escape count)", what);
  r.q.resize(size_t(n));
  const bool predict = lorenzo_coded;
  const uint8_t* esc = raw.data() + n;
  int64_t v = 0;
  for (int64_t k = 0; k < dims.z; ++k)
    for (int64_t j = 0; j < dims.y; ++j)
      for (int64_t i = 0; i < dims.x; ++i, ++v) {
        uint32_t u = raw[size_t(v)];
        if (u == kEscape) {
          u = uint32_t(esc[0]) | uint32_t(esc[1]) << 8 | uint32_t(esc[2]) << 16 | uint32_t(esc[3]) << 24;
          esc += 4;
        }
        const int64_t q = unzigzag(u) + (predict ? lorenzo(r.q.data(), dims, i, j, k) : 0);
        if (q < INT32_MIN || q > INT32_MAX) fail("{}: the residual block is corrupted (value out of range)", what);
        r.q[size_t(v)] = int32_t(q);
      }
  return r;
}

}  // namespace vnr
