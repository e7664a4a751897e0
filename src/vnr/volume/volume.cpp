// describe_volume: pick the descriptor format, apply command-line overrides, validate without
// reading the data.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/json.h"
#include "vnr/volume/dataset.h"
#include "vnr/volume/formats.h"
#include "vnr/volume/volume.h"

namespace vnr {

NonFinitePolicy parse_non_finite_policy(const std::string& name) {
  if (name == "error") return NonFinitePolicy::Error;
  if (name == "zero") return NonFinitePolicy::Zero;
  if (name == "clamp") return NonFinitePolicy::Clamp;
  fail("unknown nan policy '{}' (allowed: error, zero, clamp)", name);
}

const char* non_finite_policy_name(NonFinitePolicy p) {
  return p == NonFinitePolicy::Zero ? "zero" : p == NonFinitePolicy::Clamp ? "clamp" : "error";
}
namespace detail {

std::string dims_string(const Int3& d, int n_timesteps) {
  std::string s = fmt::format("{}x{}x{}", d.x, d.y, d.z);
  if (n_timesteps != 1) s += fmt::format("x{}", n_timesteps);
  return s;
}

bool parse_byte_order(const std::string& word, const std::string& prefix, const std::string& name) {
  const std::string l = to_lower(word);
  if (l == "little" || l == "little_endian" || l == "le") return false;
  if (l == "big" || l == "big_endian" || l == "be") return true;
  fail("{}unknown {} '{}' (allowed: little, big)", prefix, name, word);
}

}  // namespace detail

namespace {

using detail::dims_string;
using detail::Source;

constexpr uint64_t kMaxVoxels = uint64_t(1) << 40;

bool has_nrrd_magic(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return false;
  char m[7] = {};
  size_t n = std::fread(m, 1, 7, f);
  std::fclose(f);
  return n == 7 && std::memcmp(m, "NRRD000", 7) == 0;
}

Source describe_json(const std::string& path) {
  Json j = parse_json_file(path);
  try {
    if (!j.is_object()) fail("'{}': expected a JSON object", path);
    bool diva = j.contains("version") && j["version"].is_string() && j["version"].get<std::string>() == "DIVA";
    if (j.contains("dataSource") || diva) return detail::describe_scene(path, j);
    if (j.contains("file")) return detail::describe_sidecar(path, j);
  } catch (const Json::exception& e) {
    fail("'{}': malformed volume descriptor ({})", path, e.what());
  }
  fail("'{}' is neither a vnr sidecar (keys \"file\", \"dims\", \"dtype\") nor an instantvnr scene (key \"dataSource\")",
       path);
}

// The one place where size arithmetic can overflow; everything after works in checked uint64.
uint64_t checked_frame_bytes(const Int3& d, DType t, const std::string& what) {
  for (int a = 0; a < 3; ++a)
    if (d[a] <= 0) fail("{}: dims {} must all be positive", what, dims_string(d));
  uint64_t n = 0;
  if (__builtin_mul_overflow(uint64_t(d.x), uint64_t(d.y), &n) || __builtin_mul_overflow(n, uint64_t(d.z), &n))
    fail("{}: dims {} overflow a 64-bit voxel count", what, dims_string(d));
  if (n > kMaxVoxels) fail("{}: dims {} = {} voxels exceed the limit of 2^40", what, dims_string(d), n);
  return n * dtype_size(t);
}


// gzread would silently pass uncompressed bytes through; catch a mislabelled file here.
void check_gzip_magic(const VolumeDesc& d) {
  uint64_t size = file_size(d.path);
  unsigned char m[2] = {0, 0};
  bool ok = false;
  if (size >= d.gzip_start + 2) {
    if (std::FILE* f = std::fopen(d.path.c_str(), "rb")) {
      ok = std::fseek(f, long(d.gzip_start), SEEK_SET) == 0 && std::fread(m, 1, 2, f) == 2 && m[0] == 0x1f && m[1] == 0x8b;
      std::fclose(f);
    }
  }
  if (!ok) fail("'{}': encoding is gzip but the data at byte {} is not a gzip stream", d.path, d.gzip_start);
}

// The descriptor a file carries (sidecar or scene JSON, NRRD header), or for a plain raw file
// (*plain_raw set) the path alone.
Source describe_file(const std::string& path, const RawOptions& opts, bool* plain_raw) {
  const std::string ext = extension_of(path);
  *plain_raw = false;
  if (ext == ".json") return describe_json(path);
  if (ext == ".nrrd" || ext == ".nhdr" || has_nrrd_magic(path)) return detail::describe_nrrd(path);
  const std::string dataset_encoding = detail::dataset_encoding_of_extension(ext);
  if (!dataset_encoding.empty()) detail::fail_no_dataset_path(path, dataset_encoding);
  *plain_raw = true;
  if (!opts.dims || !opts.dtype)
    fail("--dims X,Y,Z and --dtype T are required for raw file '{}' (or describe it with a .json sidecar or .nhdr)",
         path);
  Source s;
  s.desc.path = path;
  return s;
}

// Command-line overrides win over any descriptor.
void apply_overrides(const RawOptions& opts, Source& s) {
  VolumeDesc& d = s.desc;
  if (opts.dims) d.dims = *opts.dims;
  if (opts.dtype) d.dtype = parse_dtype(*opts.dtype);
  if (opts.endian) d.big_endian = detail::parse_byte_order(*opts.endian, "", "--endian");
  if (opts.offset) {
    d.offset = *opts.offset;
    s.data_at_end = false;
  }
  if (opts.range_lo) d.range_lo = *opts.range_lo;
  if (opts.range_hi) d.range_hi = *opts.range_hi;
}

// The data file of time step t (d.path) must hold exactly offset + data_bytes bytes; a "byte skip -1"
// descriptor (data at the end) gets its offset from the size. Then d.offset moves to step t's frame.
void check_data_file_size(const Source& s, VolumeDesc& d, uint64_t frame, uint64_t data_bytes, int frames_in_file,
                          const std::string& what) {
  uint64_t size = 0;
  try {
    size = file_size(d.path);
  } catch (const Error& e) {
    if (s.origin.empty()) throw;
    fail("{} (data file of '{}')", e.what(), s.origin);
  }
  if (s.data_at_end) {
    if (data_bytes > size) fail("'{}' has {} bytes, expected at least {} (byte skip -1)", d.path, size, data_bytes);
    d.offset = size - data_bytes;
  }
  uint64_t expected = 0;
  if (__builtin_add_overflow(d.offset, data_bytes, &expected)) fail("{}: offset {} is too large", what, d.offset);
  if (size != expected)
    fail("'{}' has {} bytes, expected {} ({} {} + offset {})", d.path, size, expected,
         dims_string(d.dims, frames_in_file), dtype_name(d.dtype), d.offset);
  if (s.files.empty()) d.offset += uint64_t(d.timestep) * frame;
}

// An HDF5 dataset or NetCDF variable is described by its dataspace and type: of RawOptions only the
// timestep and the range apply.
Source describe_dataset_source(const detail::DatasetPath& p, const RawOptions& opts) {
  const char* layout_option =
      opts.dims ? "--dims" : opts.dtype ? "--dtype" : opts.endian ? "--endian" : opts.offset ? "--offset" : nullptr;
  if (layout_option)
    fail("{} does not apply to '{}:{}': its dims and type come from the {}", layout_option, p.file, p.name,
         p.encoding == "hdf5" ? "dataset" : "variable");
  return detail::describe_dataset(p);
}

}  // namespace

VolumeDesc describe_volume(const std::string& path, const RawOptions& opts) {
  const std::optional<detail::DatasetPath> dataset = detail::split_dataset_path(path);
  if (!dataset) file_size(path);  // missing, unreadable or a directory: says so with the path
  bool plain_raw = false;
  Source s = dataset ? describe_dataset_source(*dataset, opts) : describe_file(path, opts, &plain_raw);
  VolumeDesc& d = s.desc;
  const std::string what = s.origin.empty() ? "'" + path + "'" : "'" + s.origin + "'";
  apply_overrides(opts, s);

  const uint64_t frame = checked_frame_bytes(d.dims, d.dtype, what);
  if ((d.range_lo && !std::isfinite(*d.range_lo)) || (d.range_hi && !std::isfinite(*d.range_hi)))
    fail("{}: value range must be finite", what);
  if (d.range_lo && d.range_hi && *d.range_lo > *d.range_hi)
    fail("{}: invalid value range [{}, {}] (lo > hi)", what, *d.range_lo, *d.range_hi);

  // A plain raw file with --timestep holds as many whole frames as fit after the offset.
  if (plain_raw && opts.timestep && d.encoding == "raw") {
    uint64_t size = file_size(d.path);
    if (size > d.offset && (size - d.offset) % frame == 0 && (size - d.offset) / frame <= uint64_t(1 << 30))
      d.n_timesteps = int((size - d.offset) / frame);
  }

  // Bytes the data file must hold (in-file time series hold all timesteps).
  const int frames_in_file = s.files.empty() ? d.n_timesteps : 1;
  uint64_t data_bytes = 0;
  if (__builtin_mul_overflow(frame, uint64_t(frames_in_file), &data_bytes) || data_bytes > (uint64_t(1) << 62))
    fail("{}: {} {} is too large", what, dims_string(d.dims, frames_in_file), dtype_name(d.dtype));

  const int t = opts.timestep.value_or(0);
  if (t < 0 || t >= d.n_timesteps)
    fail("timestep {} out of range: {} has {} timestep{} (0..{})", t, what, d.n_timesteps,
         d.n_timesteps == 1 ? "" : "s", d.n_timesteps - 1);
  d.timestep = t;
  if (!s.files.empty()) d.path = s.files[size_t(t)];
  if (dataset) return d;  // the library reads the timestep's hyperslab: no byte offsets to check

  if (d.encoding == "gzip") {
    if (s.files.empty()) d.offset += uint64_t(t) * frame;
    check_gzip_magic(d);
    return d;  // the decompressed size is checked while loading
  }
  check_data_file_size(s, d, frame, data_bytes, frames_in_file, what);
  return d;
}

}  // namespace vnr
