// JSON volume descriptors: vnr/shared sidecars and instantvnr scene files (VIDI3D and DIVA).
// A sidecar's "file" may also be an array of file names: a time series with one data file per
// timestep (same dims, dtype, byte order and offset; the files must all have the same size).
#include <cmath>
#include <limits>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/volume/formats.h"

namespace vnr::detail {
namespace {

// Dims arrive as JSON numbers; accept integral values only, and keep negative / huge ones so the
// common validation can name them.
int64_t json_int(const Json& v, const std::string& what, const std::string& key) {
  if (v.is_number_integer()) {
    if (v.is_number_unsigned() && v.get<uint64_t>() > uint64_t(std::numeric_limits<int64_t>::max()))
      fail("'{}': {} value {} is too large", what, key, v.get<uint64_t>());
    return v.get<int64_t>();
  }
  if (v.is_number_float()) {
    double d = v.get<double>();
    if (std::isfinite(d) && d == std::floor(d) && std::fabs(d) < 9.0e18) return int64_t(d);
  }
  fail("'{}': {} must be an integer, got {}", what, key, v.dump());
}

double json_num(const Json& v, const std::string& what, const std::string& key) {
  if (!v.is_number()) fail("'{}': {} must be a number, got {}", what, key, v.dump());
  return v.get<double>();
}

const Json& require(const Json& j, const char* key, const std::string& what, const char* context = "") {
  if (!j.is_object() || !j.contains(key)) fail("'{}': missing \"{}\"{}", what, key, context);
  return j[key];
}

std::string json_str(const Json& v, const std::string& what, const std::string& key) {
  if (!v.is_string()) fail("'{}': {} must be a string, got {}", what, key, v.dump());
  return v.get<std::string>();
}

// {"x":..,"y":..,"z":..}
Int3 xyz_dims(const Json& v, const std::string& what, const std::string& key) {
  if (!v.is_object()) fail("'{}': {} must be an object {{\"x\",\"y\",\"z\"}}", what, key);
  Int3 d;
  const char* names[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    if (!v.contains(names[a])) fail("'{}': {} lacks \"{}\"", what, key, names[a]);
    d[a] = json_int(v[names[a]], what, key + "." + names[a]);
  }
  return d;
}

// instantvnr resolves relative paths against the working directory; vnr also tries the scene's
// own directory so that a scene next to its data works from anywhere.
std::string resolve_scene_path(const std::string& name, const std::string& json_dir) {
  if (file_exists(name)) return name;
  if (!name.empty() && name[0] != '/') {
    std::string p = join_path(json_dir, name);
    if (file_exists(p)) return p;
  }
  return "";
}

std::string first_existing(const Json& v, const std::string& what, const std::string& key,
                           const std::string& json_dir) {
  std::vector<std::string> names;
  if (v.is_string()) {
    names.push_back(v.get<std::string>());
  } else if (v.is_array() && !v.empty()) {
    for (auto& e : v) names.push_back(json_str(e, what, key + " entry"));
  } else {
    fail("'{}': {} must be a string or a non-empty array of strings", what, key);
  }
  for (auto& n : names)
    if (auto p = resolve_scene_path(n, json_dir); !p.empty()) return p;
  std::string tried;
  for (auto& n : names) tried += (tried.empty() ? "'" : ", '") + n + "'";
  fail("'{}': data file not found (tried {} relative to the working directory and to '{}')", what, tried,
       json_dir.empty() ? "." : json_dir);
}


std::pair<double, double> min_max_object(const Json& v, const std::string& what, const std::string& key,
                                         const char* lo_key, const char* hi_key) {
  if (!v.is_object() || !v.contains(lo_key) || !v.contains(hi_key))
    fail("'{}': {} must be {{\"{}\":lo,\"{}\":hi}}", what, key, lo_key, hi_key);
  return {json_num(v[lo_key], what, key + "." + lo_key), json_num(v[hi_key], what, key + "." + hi_key)};
}

Source describe_diva(const std::string& json_path, const Json& j) {
  Source s;
  s.origin = json_path;
  const std::string dir = dirname_of(json_path);
  const Json& vol = require(j, "volume", json_path, " (DIVA scene)");
  s.desc.dims = xyz_dims(require(vol, "dims", json_path, " in \"volume\""), json_path, "volume.dims");
  s.desc.dtype = parse_dtype(json_str(require(vol, "type", json_path, " in \"volume\""), json_path, "volume.type"));
  if (vol.contains("bigendian")) {
    if (!vol["bigendian"].is_boolean()) fail("'{}': volume.bigendian must be true or false", json_path);
    s.desc.big_endian = vol["bigendian"].get<bool>();
  }
  // DIVA: an array of file names is a time series (unlike VIDI3D's "first that exists").
  const Json& fn = require(vol, "filename", json_path, " in \"volume\"");
  if (fn.is_array()) {
    if (fn.empty()) fail("'{}': volume.filename is an empty array", json_path);
    for (size_t t = 0; t < fn.size(); ++t)
      s.files.push_back(first_existing(fn[t], json_path, "volume.filename", dir));
    s.desc.path = s.files[0];
    s.desc.n_timesteps = int(s.files.size());
  } else {
    s.desc.path = first_existing(fn, json_path, "volume.filename", dir);
  }
  if (vol.contains("range")) {
    auto [lo, hi] = min_max_object(vol["range"], json_path, "volume.range", "x", "y");
    s.desc.range_lo = lo;
    s.desc.range_hi = hi;
  }
  return s;
}

}  // namespace

Source describe_sidecar(const std::string& json_path, const Json& j) {
  Source s;
  s.origin = json_path;
  VolumeDesc& d = s.desc;
  const Json& file = require(j, "file", json_path);
  if (file.is_array()) {
    // A file list: one data file per timestep, all with the same dims, dtype and size.
    if (file.empty()) fail("'{}': \"file\" is an empty array (a time series lists one data file per timestep)", json_path);
    uint64_t first_size = 0;
    for (size_t t = 0; t < file.size(); ++t) {
      std::string p = join_path(dirname_of(json_path), json_str(file[t], json_path, "\"file\" entry"));
      if (!file_exists(p)) fail("'{}': data file '{}' of timestep {} does not exist", json_path, p, t);
      uint64_t size = file_size(p);
      if (t == 0) first_size = size;
      else if (size != first_size)
        fail("'{}': the files of a time series must have the same size, but '{}' (timestep {}) has {} bytes and '{}' "
             "(timestep 0) has {}",
             json_path, p, t, size, s.files[0], first_size);
      s.files.push_back(p);
    }
    d.path = s.files[0];
    d.n_timesteps = int(s.files.size());
  } else {
    d.path = join_path(dirname_of(json_path), json_str(file, json_path, "\"file\""));
  }

  const Json& dims = require(j, "dims", json_path);
  if (!dims.is_array() || (dims.size() != 3 && dims.size() != 4))
    fail("'{}': \"dims\" must be an array of 3 or 4 integers (x, y, z[, timesteps]), got {}", json_path,
         dims.dump());
  for (int a = 0; a < 3; ++a) d.dims[a] = json_int(dims[a], json_path, "\"dims\"");
  if (dims.size() == 4) {
    int64_t t = json_int(dims[3], json_path, "\"dims\"");
    if (t <= 0 || t > std::numeric_limits<int>::max())
      fail("'{}': the 4th dim (timesteps) must be a positive integer, got {}", json_path, t);
    if (!s.files.empty() && t != int64_t(s.files.size()))
      fail("'{}': the 4th dim says {} timesteps but \"file\" lists {} files", json_path, t, s.files.size());
    d.n_timesteps = int(t);
  }
  if (s.files.size() == 1) s.files.clear();  // a list of one is a plain file
  d.dtype = parse_dtype(json_str(require(j, "dtype", json_path), json_path, "\"dtype\""));
  if (j.contains("byte_order")) d.big_endian = parse_byte_order(json_str(j["byte_order"], json_path, "\"byte_order\""), "'" + json_path + "': ", "byte order");
  if (j.contains("offset")) {
    int64_t off = json_int(j["offset"], json_path, "\"offset\"");
    if (off < 0) fail("'{}': \"offset\" must not be negative", json_path);
    d.offset = uint64_t(off);
  }
  if (j.contains("spacing") && !j["spacing"].is_null()) {
    const Json& sp = j["spacing"];
    if (!sp.is_array() || sp.size() < 3) fail("'{}': \"spacing\" must be an array of 3 numbers", json_path);
    float v[3];
    for (int a = 0; a < 3; ++a) {
      v[a] = float(json_num(sp[a], json_path, "\"spacing\""));
      if (!(v[a] > 0) || !std::isfinite(v[a])) fail("'{}': \"spacing\" entries must be positive, got {}", json_path, sp.dump());
    }
    d.spacing = {v[0], v[1], v[2]};
  }
  if (j.contains("value_range") && !j["value_range"].is_null()) {
    const Json& r = j["value_range"];
    if (!r.is_array() || r.size() != 2) fail("'{}': \"value_range\" must be [lo, hi]", json_path);
    d.range_lo = json_num(r[0], json_path, "\"value_range\"");
    d.range_hi = json_num(r[1], json_path, "\"value_range\"");
  }
  return s;
}

Source describe_scene(const std::string& json_path, const Json& j) {
  std::string version = "VIDI3D";
  if (j.contains("version")) version = json_str(j["version"], json_path, "\"version\"");
  if (version == "DIVA") return describe_diva(json_path, j);
  if (version != "VIDI3D") fail("'{}': unknown scene \"version\" '{}' (allowed: VIDI3D, DIVA)", json_path, version);

  Source s;
  s.origin = json_path;
  const std::string dir = dirname_of(json_path);
  const Json& sources = require(j, "dataSource", json_path);
  if (!sources.is_array() || sources.empty()) fail("'{}': \"dataSource\" must be a non-empty array", json_path);
  // Entries after the first are time steps with the same grid (docs/MODEL_FORMAT.md section 3;
  // instantvnr's own loader fails on them, vnr reads them).
  for (size_t t = 0; t < sources.size(); ++t) {
    const Json& e = sources[t];
    std::string ctx = fmt::format(" in dataSource[{}]", t);
    if (e.contains("format")) {
      std::string f = json_str(e["format"], json_path, "dataSource.format");
      if (f != "REGULAR_GRID_RAW_BINARY")
        fail("'{}': dataSource[{}].format '{}' is not supported (only REGULAR_GRID_RAW_BINARY)", json_path, t, f);
    }
    Int3 dims = xyz_dims(require(e, "dimensions", json_path, ctx.c_str()), json_path, "dataSource.dimensions");
    DType type = parse_dtype(json_str(require(e, "type", json_path, ctx.c_str()), json_path, "dataSource.type"));
    bool big = false;
    if (e.contains("endian")) big = parse_byte_order(json_str(e["endian"], json_path, "dataSource.endian"), "'" + json_path + "': ", "byte order");
    uint64_t offset = 0;
    if (e.contains("offset")) {
      int64_t off = json_int(e["offset"], json_path, "dataSource.offset");
      if (off < 0) fail("'{}': dataSource[{}].offset must not be negative", json_path, t);
      offset = uint64_t(off);
    }
    std::string path = first_existing(require(e, "fileName", json_path, ctx.c_str()), json_path,
                                      "dataSource.fileName", dir);
    if (t == 0) {
      s.desc.dims = dims;
      s.desc.dtype = type;
      s.desc.big_endian = big;
      s.desc.offset = offset;
      s.desc.path = path;
    } else if (!(dims == s.desc.dims) || type != s.desc.dtype || big != s.desc.big_endian || offset != s.desc.offset) {
      fail("'{}': dataSource[{}] differs from dataSource[0] in dims, type, endian or offset (time steps must match)",
           json_path, t);
    }
    s.files.push_back(path);
  }
  s.desc.n_timesteps = int(s.files.size());
  if (s.files.size() == 1) s.files.clear();

  // Value range (docs/semantics.md B.1): the unnormalized key is in data units; the plain key is a fraction
  // of the type's maximum for integer data.
  if (j.contains("view") && j["view"].is_object() && j["view"].contains("volume")) {
    const Json& vol = j["view"]["volume"];
    if (vol.is_object() && vol.contains("scalarMappingRangeUnnormalized")) {
      auto [lo, hi] = min_max_object(vol["scalarMappingRangeUnnormalized"], json_path,
                                     "scalarMappingRangeUnnormalized", "minimum", "maximum");
      s.desc.range_lo = lo;
      s.desc.range_hi = hi;
    } else if (vol.is_object() && vol.contains("scalarMappingRange")) {
      auto [lo, hi] = min_max_object(vol["scalarMappingRange"], json_path, "scalarMappingRange", "minimum", "maximum");
      double scale = dtype_is_integer(s.desc.dtype) ? dtype_max(s.desc.dtype) : 1.0;
      s.desc.range_lo = lo * scale;
      s.desc.range_hi = hi * scale;
    }
  }
  return s;
}

}  // namespace vnr::detail
