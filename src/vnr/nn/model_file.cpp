#include "vnr/nn/model_file.h"
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/core/half.h"
#include "vnr/nn/header_codec.h"
#include "vnr/nn/param_codec.h"

// Both formats store little-endian numbers and this file copies them with memcpy.
static_assert(std::endian::native == std::endian::little, "model_file.cpp assumes a little-endian host");

namespace vnr {
namespace {

// ---- .vnr layout constants (docs/MODEL_FORMAT.md) ----------------------------------------------
constexpr char kMagic[8] = {'V', 'N', 'R', 'M', 'O', 'D', 'E', 'L'};
constexpr char kEndMagic[8] = {'V', 'N', 'R', 'E', 'N', 'D', '\0', '\0'};
constexpr uint32_t kFormatVersion = 3;     // the newest this vnr reads, written for compact models
constexpr uint32_t kPlainFormatVersion = 1;  // written when a model needs nothing of versions 2 and 3
constexpr uint32_t kCompressedHeaderVersion = 3;  // from here: zstd-coded header, blocks unpadded
constexpr uint64_t kMaxHeaderJsonBytes = uint64_t(1) << 26;  // a decoded header beyond 64 MiB is damage
constexpr const char* kMacrocellCodec = "u8-zstd";
constexpr uint64_t kPreambleBytes = 24;  // magic, version, flags, header length
constexpr uint64_t kTrailerBytes = 12;   // CRC-32 + end magic
// Versions 1 and 2 start every data block on a 64-byte boundary (mappable as arrays); version 3's
// blocks are compressed streams, so they follow one another (the padding took up to 0.2 kB a file).
constexpr uint64_t block_alignment(uint32_t version) { return version >= kCompressedHeaderVersion ? 1 : 64; }
constexpr int kMaxHeaderDepth = 256;     // nlohmann parses recursively: refuse absurd nesting
constexpr int64_t kMaxDim = std::numeric_limits<int32_t>::max();  // instantvnr stores dims as int
constexpr uint64_t kMaxVoxels = uint64_t(1) << 40;  // the volume loaders' limit (volume.cpp)

// instantvnr: 16 voxels per macro-cell per axis (MACROCELL_SIZE_MIP = 4).
constexpr int64_t kIvnrMacrocellVoxels = 16;

std::string one_line(std::string s) {
  std::replace(s.begin(), s.end(), '\n', ' ');
  return s;
}

template <typename T>
T load_le(const std::string& buf, uint64_t off) {
  T v;
  std::memcpy(&v, buf.data() + off, sizeof(T));
  return v;
}

template <typename T>
void append_le(std::string& out, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  out.append(b, sizeof(T));
}

// Product of the three dims, or false on overflow / non-positive entries.
bool cell_count(const Int3& d, uint64_t& out) {
  uint64_t c = 1;
  for (int a = 0; a < 3; ++a) {
    if (d[a] <= 0) return false;
    if (__builtin_mul_overflow(c, uint64_t(d[a]), &c)) return false;
  }
  out = c;
  return true;
}

bool has_macrocells(const ModelFile& m) { return !(m.macrocell_dims == Int3{}); }

// Checks the in-memory model before anything is written, so a bad model never reaches disk.
void validate_for_write(const std::string& path, const ModelFile& m) {
  if (!m.config.is_object()) fail("cannot write '{}': the model config is not a JSON object", path);
  for (int a = 0; a < 3; ++a)
    if (m.dims[a] <= 0 || m.dims[a] > kMaxDim)
      fail("cannot write '{}': invalid volume dims {}x{}x{}", path, m.dims.x, m.dims.y, m.dims.z);
  if (!std::isfinite(m.lo) || !std::isfinite(m.hi))
    fail("cannot write '{}': value range [{}, {}] is not finite", path, m.lo, m.hi);
  if (has_macrocells(m)) {
    uint64_t count = 0;
    bool ok = cell_count(m.macrocell_dims, count);
    for (int a = 0; a < 3; ++a) ok = ok && m.macrocell_dims[a] <= kMaxDim;
    if (!ok)
      fail("cannot write '{}': invalid macro-cell dims {}x{}x{}", path, m.macrocell_dims.x,
           m.macrocell_dims.y, m.macrocell_dims.z);
    if (m.macrocell_ranges.size() != 2 * count)
      fail("cannot write '{}': {} macro-cell values for {} cells (expected {})", path,
           m.macrocell_ranges.size(), count, 2 * count);
  } else if (!m.macrocell_ranges.empty()) {
    fail("cannot write '{}': macro-cell values given without macro-cell dims", path);
  }
}

// Refuses JSON nested deeper than kMaxHeaderDepth before handing it to the recursive parser.
bool nesting_ok(const std::string& s) {
  int depth = 0;
  bool in_str = false, esc = false;
  for (char c : s) {
    if (in_str) {
      if (esc) esc = false;
      else if (c == '\\') esc = true;
      else if (c == '"') in_str = false;
    } else if (c == '"') {
      in_str = true;
    } else if (c == '[' || c == '{') {
      if (++depth > kMaxHeaderDepth) return false;
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
  return true;
}

Json int3_array(const Int3& d) { return Json::array({d.x, d.y, d.z}); }

// [x,y,z] of positive integers (header "dims" / "macrocell_dims").
Int3 parse_int3_array(const Json& j, const std::string& path, const char* key) {
  if (!j.is_array() || j.size() != 3) fail("'{}' has an invalid header: '{}' is not [x, y, z]", path, key);
  Int3 d;
  for (int a = 0; a < 3; ++a) {
    const Json& v = j[size_t(a)];
    if (!v.is_number_integer() || v.get<int64_t>() <= 0 || v.get<int64_t>() > kMaxDim)
      fail("'{}' has an invalid header: '{}' must hold three positive integers", path, key);
    d[a] = v.get<int64_t>();
  }
  return d;
}

// A model's volume dims: no volume vnr loads has more than 2^40 voxels, and a hostile header must not
// reach a decode whose voxel count overflows or asks for terabytes.
Int3 checked_volume_dims(const Int3& d, const std::string& path) {
  uint64_t n = 0;
  if (!cell_count(d, n) || n > kMaxVoxels)
    fail("'{}' has an invalid header: volume dims {}x{}x{} = {:.4g} voxels exceed the limit of 2^40", path, d.x, d.y,
         d.z, double(d.x) * double(d.y) * double(d.z));
  return d;
}

// {"x","y","z"} of positive integers (instantvnr "dims").
Int3 parse_int3_object(const Json& j, const std::string& path, const char* key) {
  if (!j.is_object()) fail("'{}': '{}' is not an object {{x, y, z}}", path, key);
  Int3 d;
  const char* names[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    auto it = j.find(names[a]);
    if (it == j.end() || !it->is_number_integer() || it->get<int64_t>() <= 0 || it->get<int64_t>() > kMaxDim)
      fail("'{}': '{}.{}' must be a positive integer", path, key, names[a]);
    d[a] = it->get<int64_t>();
  }
  return d;
}

// ---- .vnr reading ---------------------------------------------------------------------------

// The preamble's checks, in order: magic, size, version, header size; then the end magic and, for a
// complete file, the CRC. Returns the header's byte count; *complete says whether the end magic is there.
uint64_t check_vnr_preamble(const std::string& path, const std::string& buf, bool* complete_out,
                            uint32_t* version_out) {
  const uint64_t size = buf.size();
  const uint64_t min_size = kPreambleBytes + kTrailerBytes;
  // A short file that starts like the magic is a truncated model, anything else is not a model.
  if (size < sizeof kMagic) {
    if (std::memcmp(buf.data(), kMagic, size_t(size)) == 0)
      fail("'{}' is truncated: expected at least {} bytes, found {}", path, min_size, size);
    fail("'{}' is not a vnr model file", path);
  }
  if (std::memcmp(buf.data(), kMagic, sizeof kMagic) != 0) fail("'{}' is not a vnr model file", path);
  if (size < kPreambleBytes) fail("'{}' is truncated: expected at least {} bytes, found {}", path, min_size, size);

  // The version comes before the checksum: a newer format may protect its data differently.
  const uint32_t version = load_le<uint32_t>(buf, 8);
  if (version > kFormatVersion)
    fail("'{}' was written by a newer vnr (format {} > {}); upgrade vnr to read it", path, version, kFormatVersion);
  if (version == 0) fail("'{}' is corrupted (invalid format version 0)", path);
  // Offset 12: reserved flags, written 0; version-1 readers ignore them (still CRC-protected).
  const uint64_t header_bytes = load_le<uint64_t>(buf, 16);
  if (header_bytes > size) fail("'{}' is truncated: expected more than {} bytes, found {}", path, size, size);
  if (kPreambleBytes + header_bytes + kTrailerBytes > size)
    fail("'{}' is truncated: expected at least {} bytes, found {}", path,
         kPreambleBytes + header_bytes + kTrailerBytes, size);

  // A complete file ends with the end magic; then the CRC decides, before any content is trusted.
  const bool complete = std::memcmp(buf.data() + size - sizeof kEndMagic, kEndMagic, sizeof kEndMagic) == 0;
  if (complete) {
    uint32_t stored = load_le<uint32_t>(buf, size - kTrailerBytes);
    if (crc32_of(buf.data(), size_t(size - kTrailerBytes)) != stored)
      fail("'{}' is corrupted (checksum mismatch)", path);
  }
  *complete_out = complete;
  *version_out = version;
  return header_bytes;
}

// Without the end magic the header may still be intact (the file was cut short later on): parse
// it to report the expected size; if it does not parse, the file is damaged either way.
Json parse_vnr_header(const std::string& path, const std::string& buf, uint64_t header_bytes, bool complete,
                      uint32_t version) {
  const std::string_view stored(buf.data() + kPreambleBytes, size_t(header_bytes));
  std::string header_text;
  if (version < kCompressedHeaderVersion) {
    header_text = stored;
  } else {
    try {
      header_text = decompress_vnr_header(path, stored, kMaxHeaderJsonBytes);
    } catch (const Error&) {
      if (!complete) fail("'{}' is truncated or corrupted (end marker missing, header unreadable)", path);
      throw;
    }
  }
  Json h;
  if (!nesting_ok(header_text)) fail("'{}' is corrupted (header JSON nested too deeply)", path);
  try {
    h = Json::parse(header_text);
  } catch (const Json::exception& e) {
    if (!complete) fail("'{}' is truncated or corrupted (end marker missing, header unreadable)", path);
    fail("'{}' is corrupted (invalid header JSON: {})", path, one_line(e.what()));
  }
  if (!h.is_object()) fail("'{}' is corrupted (header is not a JSON object)", path);
  return h;
}

// The header's descriptive fields: config, dims, and the optional dtype, value_range and training.
void read_vnr_descriptors(const std::string& path, const Json& h, ModelFile& m) {
  auto cfg = h.find("config");
  if (cfg == h.end() || !cfg->is_object()) fail("'{}' has an invalid header: 'config' must be an object", path);
  m.config = *cfg;
  auto dims = h.find("dims");
  if (dims == h.end()) fail("'{}' has an invalid header: 'dims' missing", path);
  m.dims = checked_volume_dims(parse_int3_array(*dims, path, "dims"), path);
  if (auto dt = h.find("dtype"); dt != h.end()) {
    if (!dt->is_string()) fail("'{}' has an invalid header: 'dtype' must be a string", path);
    try {
      m.source_dtype = parse_dtype(dt->get<std::string>());
    } catch (const Error& e) {
      fail("'{}' has an invalid header: {}", path, e.what());
    }
  }
  auto vr = h.find("value_range");
  if (vr != h.end()) {
    if (!vr->is_array() || vr->size() != 2 || !(*vr)[0].is_number() || !(*vr)[1].is_number())
      fail("'{}' has an invalid header: 'value_range' must be [lo, hi]", path);
    m.lo = (*vr)[0].get<double>();
    m.hi = (*vr)[1].get<double>();
  }
  auto tr = h.find("training");
  if (tr != h.end()) m.training = *tr;
}

// Version-2 header keys (docs/MODEL_FORMAT.md 1.5): the compressed parameter block and the residuals.
struct V2Blocks {
  bool compressed = false;
  uint64_t params_bytes = 0;  // of the compressed block
  Json segments;
  bool residuals = false;
  uint64_t residual_bytes = 0;
  bool compact_macrocells = false;
  uint64_t macrocell_bytes = 0;  // of the compressed macro-cell block
};

uint64_t header_count(const Json& obj, const char* key, const std::string& path, const char* where) {
  auto it = obj.find(key);
  if (it == obj.end() || !it->is_number_integer() || it->get<int64_t>() < 0)
    fail("'{}' has an invalid header: '{}' must be a non-negative integer", path, where);
  return it->get<uint64_t>();
}

V2Blocks parse_v2_keys(const std::string& path, const Json& h, uint32_t version) {
  V2Blocks v;
  if (version < 2) return v;  // version-1 readers ignored unknown keys: so does this one for v1 files
  if (auto pe = h.find("params_encoding"); pe != h.end() && !pe->is_null()) {
    if (!pe->is_object() || !pe->contains("codec") ||
        ((*pe)["codec"] != kParamsZstdCodec && (*pe)["codec"] != kParamsContextCodec))
      fail("'{}' has an unsupported params_encoding {} (this vnr reads codecs \"{}\" and \"{}\")", path,
           one_line(pe->dump()), kParamsZstdCodec, kParamsContextCodec);
    v.compressed = true;
    v.params_bytes = header_count(*pe, "bytes", path, "params_encoding.bytes");
    v.segments = pe->contains("segments") ? (*pe)["segments"] : Json();
  }
  if (auto me = h.find("macrocell_encoding"); me != h.end() && !me->is_null()) {
    if (!me->is_object() || !me->contains("codec") || (*me)["codec"] != kMacrocellCodec)
      fail("'{}' has an unsupported macrocell_encoding {} (this vnr reads codec \"{}\")", path,
           one_line(me->dump()), kMacrocellCodec);
    v.compact_macrocells = true;
    v.macrocell_bytes = header_count(*me, "bytes", path, "macrocell_encoding.bytes");
  }
  if (auto r = h.find("residuals"); r != h.end() && !r->is_null()) {
    if (!r->is_object()) fail("'{}' has an invalid header: 'residuals' must be an object", path);
    v.residuals = true;
    v.residual_bytes = header_count(h, "residuals_bytes", path, "residuals_bytes");
  }
  return v;
}

ModelFile parse_vnr(const std::string& path, const std::string& buf) {
  const uint64_t size = buf.size();
  bool complete = false;
  uint32_t version = 0;
  const uint64_t header_bytes = check_vnr_preamble(path, buf, &complete, &version);
  const Json h = parse_vnr_header(path, buf, header_bytes, complete, version);
  ModelFile m;
  uint64_t n_params = 0, mc_count = 0;
  try {
    n_params = header_count(h, "n_params", path, "n_params");
    auto pd = h.find("params_dtype");
    if (pd != h.end() && !(pd->is_string() && pd->get<std::string>() == "float16"))
      fail("'{}' has an unsupported params_dtype {} (this vnr reads \"float16\")", path, pd->dump());
    auto mcd = h.find("macrocell_dims");
    if (mcd != h.end() && !mcd->is_null()) {
      m.macrocell_dims = parse_int3_array(*mcd, path, "macrocell_dims");
      if (!cell_count(m.macrocell_dims, mc_count)) fail("'{}' is corrupted (macro-cell dims overflow)", path);
    }
    const V2Blocks v2 = parse_v2_keys(path, h, version);

    // 128-bit so that a damaged count cannot wrap around into a plausible size.
    using u128 = unsigned __int128;
    const uint64_t alignment = block_alignment(version);
    auto align = [alignment](u128 v) { return (v + alignment - 1) / alignment * alignment; };
    const u128 params_off = align(u128(kPreambleBytes) + header_bytes);
    u128 end = params_off + (v2.compressed ? u128(v2.params_bytes) : u128(n_params) * 2);
    u128 mc_off = 0, res_off = 0;
    if (mc_count) {
      mc_off = align(end);
      end = mc_off + (v2.compact_macrocells ? u128(v2.macrocell_bytes) : u128(mc_count) * 8);
    } else if (v2.compact_macrocells) {
      fail("'{}' has an invalid header: 'macrocell_encoding' without 'macrocell_dims'", path);
    }
    if (v2.residuals) {
      res_off = align(end);
      end = res_off + v2.residual_bytes;
    }
    const u128 expected = end + kTrailerBytes;
    if (expected != size) {
      std::string exp_str = expected > std::numeric_limits<uint64_t>::max()
                                ? std::string("more than 2^64")
                                : std::to_string(uint64_t(expected));
      if (expected > size && !complete)
        fail("'{}' is truncated: expected {} bytes, found {}", path, exp_str, size);
      fail("'{}' is corrupted (header describes {} bytes, file has {})", path, exp_str, size);
    }
    if (!complete) fail("'{}' is corrupted (end marker missing)", path);
    read_vnr_descriptors(path, h, m);
    if (v2.compressed) {
      m.params = decode_params(path, buf.data() + size_t(params_off), v2.params_bytes, v2.segments, n_params,
                               m.param_segments);
      restore_segment_layouts(m.config, m.param_segments);
    } else {
      m.params.resize(size_t(n_params));
      if (n_params) std::memcpy(m.params.data(), buf.data() + size_t(params_off), size_t(2 * n_params));
    }
    if (v2.compact_macrocells) {
      m.macrocell_ranges = decode_macrocells_u8(path, buf.data() + size_t(mc_off), v2.macrocell_bytes, mc_count);
      m.compact_macrocells = true;
    } else {
      m.macrocell_ranges.resize(size_t(2 * mc_count));
      if (mc_count) std::memcpy(m.macrocell_ranges.data(), buf.data() + size_t(mc_off), size_t(8 * mc_count));
    }
    if (v2.residuals) {
      m.residuals_meta = h["residuals"];
      m.residuals_bytes.assign(buf.begin() + ptrdiff_t(res_off), buf.begin() + ptrdiff_t(res_off + v2.residual_bytes));
    }
  } catch (const Json::exception& e) {
    fail("'{}' has an invalid header ({})", path, one_line(e.what()));
  }
  return m;
}

// ---- instantvnr BSON ------------------------------------------------------------------------

Json default_ivnr_optimizer() {
  return Json{{"otype", "ExponentialDecay"},
              {"decay_start", 2000},
              {"decay_interval", 1000},
              {"decay_base", 0.99},
              {"nested",
               {{"otype", "Adam"},
                {"learning_rate", 5e-3},
                {"beta1", 0.9},
                {"beta2", 0.999},
                {"epsilon", 1e-15},
                {"l2_reg", 1e-6}}}};
}

// Cell size in normalised [0,1] object coordinates. instantvnr computes it in float
// (16.f / dims) and nlohmann widens that float to a BSON double, so do the same to match its
// files bit for bit. A non-instantvnr grid is taken as an even split of the volume.
double macrocell_spacing(int64_t vol_dim, int64_t mc_dim) {
  if (mc_dim == (vol_dim + kIvnrMacrocellVoxels - 1) / kIvnrMacrocellVoxels)
    return double(float(kIvnrMacrocellVoxels) / float(vol_dim));
  return double(1.0f / float(mc_dim));
}

// params_binary of n parameters: fp16 ("__half", the pinned fork's untagged default) or binary32
// ("float", tcnn head's tag), converted to fp16.
void read_ivnr_params(const std::string& path, const Json& p, uint64_t n, const Json::binary_t& bytes,
                      ModelFile& m) {
  std::string ptype = "__half";
  if (auto pt = p.find("params_type"); pt != p.end()) ptype = pt->get<std::string>();
  if (ptype == "__half") {
    if (n > bytes.size() / 2 || bytes.size() != 2 * n)
      fail("'{}': params_binary holds {} bytes, expected 2*n_params = {}", path, bytes.size(),
           n > bytes.size() ? std::string("2*") + std::to_string(n) : std::to_string(2 * n));
    m.params.resize(size_t(n));
    if (n) std::memcpy(m.params.data(), bytes.data(), size_t(2 * n));
  } else if (ptype == "float") {
    if (n > bytes.size() / 4 || bytes.size() != 4 * n)
      fail("'{}': params_binary holds {} bytes, expected 4*n_params = {}", path, bytes.size(),
           n > bytes.size() ? std::string("4*") + std::to_string(n) : std::to_string(4 * n));
    std::vector<float> f(static_cast<size_t>(n));
    if (n) std::memcpy(f.data(), bytes.data(), size_t(4 * n));
    m.params.resize(size_t(n));
    floats_to_halves(f.data(), m.params.data(), size_t(n));
  } else {
    fail("'{}': unsupported params_type '{}' (expected \"__half\" or \"float\")", path, ptype);
  }
}

// "macrocell": {"dims", "data"}: float32 (min - 1, max + 1) pairs per cell.
void read_ivnr_macrocells(const std::string& path, const Json& mc, ModelFile& m) {
  if (!mc.is_object() || !mc.contains("dims") || !mc.contains("data"))
    fail("'{}': 'macrocell' needs 'dims' and 'data'", path);
  Int3 d = parse_int3_object(mc["dims"], path, "macrocell.dims");
  const Json& data = mc["data"];
  if (!data.is_binary()) fail("'{}': macrocell.data is not a BSON binary", path);
  const auto& mb = data.get_binary();
  uint64_t count = 0;
  if (!cell_count(d, count) || count > mb.size() / 8 || mb.size() != 8 * count)
    fail("'{}': macrocell.data holds {} bytes, expected 8 per cell for {}x{}x{} cells", path, mb.size(), d.x,
         d.y, d.z);
  m.macrocell_dims = d;
  m.macrocell_ranges.resize(size_t(2 * count));
  std::memcpy(m.macrocell_ranges.data(), mb.data(), size_t(8 * count));
  // Stored as (min - 1, max + 1) against a zero-filled buffer (docs/MODEL_FORMAT.md 2.1); undo it in
  // float, as instantvnr does. An untouched (0,0) cell decodes to the empty range (1,-1).
  for (size_t i = 0; i < m.macrocell_ranges.size(); i += 2) {
    m.macrocell_ranges[i] = m.macrocell_ranges[i] + 1.0f;
    m.macrocell_ranges[i + 1] = m.macrocell_ranges[i + 1] - 1.0f;
  }
}

ModelFile parse_instantvnr(const std::string& path, const std::string& buf, bool sniffed) {
  Json root;
  try {
    root = Json::from_bson(buf.begin(), buf.end());
  } catch (const Json::exception& e) {
    if (sniffed)
      fail("'{}' is neither a vnr model file nor an instantvnr params file (invalid BSON: {})", path,
           one_line(e.what()));
    fail("'{}' is not a valid instantvnr params file (invalid BSON: {})", path, one_line(e.what()));
  }

  ModelFile m;
  try {
    if (!root.is_object()) fail("'{}': the BSON document is not an object", path);
    // Legacy files keep n_params / params_binary at the root instead of under "parameters".
    const Json& p = root.contains("parameters") ? root["parameters"] : root;
    if (!p.is_object()) fail("'{}': 'parameters' is not an object", path);
    auto np = p.find("n_params");
    auto pb = p.find("params_binary");
    if (np == p.end() || pb == p.end()) fail("'{}': no n_params / params_binary, not an instantvnr params file", path);
    if (!np->is_number_integer() || np->get<int64_t>() < 0)
      fail("'{}': n_params must be a non-negative integer", path);
    if (!pb->is_binary()) fail("'{}': params_binary is not a BSON binary", path);
    const uint64_t n = np->get<uint64_t>();
    const auto& bytes = pb->get_binary();
    read_ivnr_params(path, p, n, bytes, m);

    if (auto v = root.find("volume"); v != root.end()) {
      if (!v->is_object() || !v->contains("dims")) fail("'{}': 'volume' has no 'dims'", path);
      m.dims = checked_volume_dims(parse_int3_object((*v)["dims"], path, "volume.dims"), path);
    }

    if (auto mc = root.find("macrocell"); mc != root.end()) read_ivnr_macrocells(path, *mc, m);

    m.config = Json::object();
    if (auto md = root.find("model"); md != root.end()) {
      if (!md->is_object()) fail("'{}': 'model' is not an object", path);
      m.config = *md;
    }
    if (!m.config.contains("optimizer")) m.config["optimizer"] = default_ivnr_optimizer();
  } catch (const Json::exception& e) {
    fail("'{}': invalid instantvnr params file ({})", path, one_line(e.what()));
  }
  m.source_dtype = DType::Float32;
  m.lo = 0;
  m.hi = 1;
  m.training = nullptr;
  return m;
}

bool looks_like_vnr(const std::string& buf) {
  size_t n = std::min(buf.size(), sizeof kMagic);
  return n > 0 && std::memcmp(buf.data(), kMagic, n) == 0;
}

}  // namespace

// ---- public API -----------------------------------------------------------------------------

// The whole file in memory: write_vnr writes it atomically, vnr_file_bytes measures it.
static std::string encode_vnr(const std::string& path, const ModelFile& m) {
  validate_for_write(path, m);
  if (!m.residuals_meta.is_null() && !m.residuals_meta.is_object())
    fail("cannot write '{}': the residuals description is not a JSON object", path);
  if (m.residuals_meta.is_null() && !m.residuals_bytes.empty())
    fail("cannot write '{}': residual bytes given without their description", path);
  const bool compressed = !m.param_segments.empty();
  const bool residuals = !m.residuals_meta.is_null();
  const bool compact_mc = m.compact_macrocells && has_macrocells(m) && macrocells_fit_u8(m.macrocell_ranges);
  const std::string mc_block = compact_mc ? encode_macrocells_u8(m.macrocell_ranges) : std::string();
  Json h = Json::object();
  h["config"] = m.config;
  h["dims"] = int3_array(m.dims);
  h["dtype"] = dtype_name(m.source_dtype);
  h["value_range"] = Json::array({m.lo, m.hi});
  h["n_params"] = uint64_t(m.params.size());
  h["params_dtype"] = "float16";
  std::string params_block;
  if (compressed) {
    Json segments;
    std::string codec;
    params_block = encode_params(m.params, m.param_segments, segments, &codec);
    h["params_encoding"] = {{"codec", codec}, {"bytes", uint64_t(params_block.size())},
                            {"segments", std::move(segments)}};
  } else {
    params_block.assign(reinterpret_cast<const char*>(m.params.data()), m.params.size() * 2);
  }
  if (has_macrocells(m)) h["macrocell_dims"] = int3_array(m.macrocell_dims);
  if (compact_mc) h["macrocell_encoding"] = {{"codec", kMacrocellCodec}, {"bytes", uint64_t(mc_block.size())}};
  if (residuals) {
    h["residuals"] = m.residuals_meta;
    h["residuals_bytes"] = uint64_t(m.residuals_bytes.size());
  }
  if (!m.training.is_null()) h["training"] = m.training;
#ifdef VNR_VERSION
  h["vnr_version"] = VNR_VERSION;
#endif
  // A model that needs nothing of the later versions stays version 1, byte for byte as older vnr
  // wrote it; a compact one is version 3, whose coded header saves it about 2 kB.
  const uint32_t version = compressed || residuals || compact_mc ? kFormatVersion : kPlainFormatVersion;
  // replace: a stray invalid UTF-8 byte in a user string must not make the model unsavable.
  const std::string json = h.dump(-1, ' ', false, Json::error_handler_t::replace);
  const std::string header = version >= kCompressedHeaderVersion ? compress_vnr_header(json) : json;

  std::string out(kMagic, sizeof kMagic);
  append_le<uint32_t>(out, version);
  append_le<uint32_t>(out, 0);  // reserved flags
  append_le<uint64_t>(out, header.size());
  const uint64_t alignment = block_alignment(version);
  auto pad = [&out, alignment] { out.resize(size_t(next_multiple(out.size(), alignment)), '\0'); };
  out += header;
  pad();
  out += params_block;
  if (has_macrocells(m)) {
    pad();
    if (compact_mc) out += mc_block;
    else out.append(reinterpret_cast<const char*>(m.macrocell_ranges.data()), m.macrocell_ranges.size() * 4);
  }
  if (residuals) {
    pad();
    out.append(reinterpret_cast<const char*>(m.residuals_bytes.data()), m.residuals_bytes.size());
  }
  append_le<uint32_t>(out, crc32_of(out.data(), out.size()));
  out.append(kEndMagic, sizeof kEndMagic);
  return out;
}

void write_vnr(const std::string& path, const ModelFile& m) { write_file_atomic(path, encode_vnr(path, m)); }

uint64_t vnr_file_bytes(const ModelFile& m) { return encode_vnr("<model>", m).size(); }

ModelFile read_vnr(const std::string& path) { return parse_vnr(path, read_file(path)); }

void write_instantvnr(const std::string& path, const ModelFile& m) {
  validate_for_write(path, m);
  // BSON sizes are int32: refuse what nlohmann would otherwise encode with a wrapped length.
  const uint64_t payload = uint64_t(m.params.size()) * 2 + uint64_t(m.macrocell_ranges.size()) * 4;
  if (payload > uint64_t(std::numeric_limits<int32_t>::max()) - (1u << 20))
    fail("cannot write '{}': {} bytes of parameters exceed the 2 GiB BSON limit of instantvnr files", path,
         payload);

  auto xyz = [](const Int3& d) { return Json{{"x", d.x}, {"y", d.y}, {"z", d.z}}; };
  Json root = Json::object();
  root["volume"] = {{"dims", xyz(m.dims)}};

  // instantvnr always writes a macrocell but its loader skips the key when absent, so a model
  // without macro-cells omits it rather than inventing ranges (docs/MODEL_FORMAT.md).
  if (has_macrocells(m)) {
    std::vector<uint8_t> data(m.macrocell_ranges.size() * 4);
    std::vector<float> enc(m.macrocell_ranges.size());
    for (size_t i = 0; i < enc.size(); i += 2) {
      enc[i] = m.macrocell_ranges[i] - 1.0f;
      enc[i + 1] = m.macrocell_ranges[i + 1] + 1.0f;
    }
    if (!enc.empty()) std::memcpy(data.data(), enc.data(), data.size());
    Json spacings = {{"x", macrocell_spacing(m.dims.x, m.macrocell_dims.x)},
                     {"y", macrocell_spacing(m.dims.y, m.macrocell_dims.y)},
                     {"z", macrocell_spacing(m.dims.z, m.macrocell_dims.z)}};
    root["macrocell"] = {{"groundtruth", false},
                         {"dims", xyz(m.macrocell_dims)},
                         {"spacings", spacings},
                         {"data", Json::binary(std::move(data))}};
  }

  std::vector<uint8_t> pbytes(m.params.size() * 2);
  if (!pbytes.empty()) std::memcpy(pbytes.data(), m.params.data(), pbytes.size());
  root["parameters"] = {{"n_params", int64_t(m.params.size())}, {"params_binary", Json::binary(std::move(pbytes))}};

  // The model object mirrors instantvnr's serialize_model(): loss/encoding/network, no optimizer.
  Json model = Json::object();
  for (const char* k : {"loss", "encoding", "network"}) {
    auto it = m.config.find(k);
    model[k] = it != m.config.end() ? *it : Json::object();
  }
  root["model"] = std::move(model);

  std::vector<uint8_t> bson;
  try {
    bson = Json::to_bson(root);
  } catch (const Json::exception& e) {
    fail("cannot write '{}': {}", path, one_line(e.what()));
  }
  write_file_atomic(path, std::string_view(reinterpret_cast<const char*>(bson.data()), bson.size()));
}

ModelFile read_instantvnr(const std::string& path) { return parse_instantvnr(path, read_file(path), false); }

ModelFile read_model(const std::string& path) {
  std::string buf = read_file(path);
  if (looks_like_vnr(buf)) return parse_vnr(path, buf);
  if (buf.empty()) fail("'{}' is empty, not a model file", path);
  return parse_instantvnr(path, buf, true);
}

}  // namespace vnr
