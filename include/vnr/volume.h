#pragma once
// vnr::Volume: a scalar volume in memory, normalised to [0, 1] with its value range in original units
// (docs/semantics.md B.1): dims, source_dtype, the range [lo, hi], the normalised values `data` (x
// fastest) and view_of() -> GridView, the POD every per-sample lookup (grid_lookup) reads; where it
// comes from (VolumeDesc), the ways to make one, and streaming a file that need not fit in memory.
// Self-contained: it includes no header of the library's layers.
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>
#include "vnr/dtype.h"
#include "vnr/grid_view.h"
#include "vnr/hd.h"
#include "vnr/math.h"
#include "vnr/memory.h"

namespace vnr {

// How NaN / Inf in float data are treated when loading. Default: error.
enum class NonFinitePolicy { Error, Zero, Clamp };
// "error" | "zero" | "clamp" (the CLI's --nan, Python's nan=); anything else fails with that list.
NonFinitePolicy parse_non_finite_policy(const std::string& name);
const char* non_finite_policy_name(NonFinitePolicy p);

// Where a volume comes from, everything needed to read it. Produced by describe_volume().
struct VolumeDesc {
  std::string path;          // the raw data file (or the .nrrd file for NRRD)
  Int3 dims;                 // voxels per axis, x fastest
  DType dtype = DType::UInt8;
  bool big_endian = false;
  uint64_t offset = 0;       // bytes to skip before the first voxel (after timestep selection)
  std::string encoding = "raw";  // "raw", "gzip" (NRRD), "hdf5" or "netcdf" (then `path` is the container file)
  std::string dataset;       // hdf5: the dataset's path in the file ("/group/data"); netcdf: the variable
  uint64_t gzip_start = 0;   // gzip: where the compressed stream starts in `path`; `offset` then
                             // counts decompressed bytes
  int n_timesteps = 1;       // a 4th sidecar dim, or a 4-D dataset's first axis
  int timestep = 0;          // which one `offset` points at
  std::optional<double> range_lo, range_hi;  // explicit value range in original units (B.1)
  Vec3f spacing{1, 1, 1};
};

// Overrides from the command line: --dims X,Y,Z --dtype T --endian little|big --offset N --timestep T
// --range LO,HI. For a plain raw file dims and dtype are required.
struct RawOptions {
  std::optional<Int3> dims;
  std::optional<std::string> dtype;
  std::optional<std::string> endian;
  std::optional<uint64_t> offset;
  std::optional<int> timestep;
  std::optional<double> range_lo, range_hi;
};

// Understands: vnr/shared JSON sidecars ({"file","dims","dtype","byte_order",...}), instantvnr scene
// JSON ({"dataSource":[...], "view":{"volume":{"scalarMappingRange..."}}}), NRRD (.nrrd/.nhdr, raw
// or gzip), HDF5 datasets "FILE.h5:/group/dataset" (.h5/.hdf5/.he5) and NetCDF variables
// "FILE.nc:variable" (.nc/.nc4) -- C-order (nz, ny, nx), x = the last axis; 4-D (nt, nz, ny, nx) is
// a time series; RawOptions may set only timestep and range for them -- and plain raw files (with
// RawOptions). Validates everything it can without reading
// the data: file size vs dims x dtype (message states expected and actual bytes), zero or
// overflowing dims, unknown dtype, unreadable file.
VolumeDesc describe_volume(const std::string& path, const RawOptions& opts = {});

// A volume in memory, normalised to [0,1] with u = clamp((v - lo)/(hi - lo), 0, 1) (docs/semantics.md B.1).
// A constant volume (hi == lo) maps to 0.
struct Volume {
  Int3 dims;
  DType source_dtype = DType::Float32;
  double lo = 0, hi = 1;          // value range in original units
  big_vector<float> data;        // normalised values, x fastest (huge pages: random sampling)
  Vec3f spacing{1, 1, 1};
  uint64_t source_bytes() const { return dims.count() * dtype_size(source_dtype); }
};

struct LoadOptions {
  NonFinitePolicy non_finite = NonFinitePolicy::Error;
};

Volume load_volume(const VolumeDesc& desc, const LoadOptions& opts = {});

// The grid view of a loaded volume (vnr/grid_view.h: GridView, grid_lookup).
inline GridView view_of(const Volume& v) {
  return GridView{v.data.data(), int32_t(v.dims.x), int32_t(v.dims.y), int32_t(v.dims.z)};
}

// ---- streaming (volume/stream.cpp): the same normalisation as load_volume, bit for bit, so a streamed
// evaluation sees the same numbers as an in-memory one (normalised values at arbitrary voxels:
// RawVolumeFile, volume/raw_access.h).

// A value range in original units.
struct ValueRange {
  double lo = 0, hi = 0;
};

// The range load_volume(desc, opts) would give: explicit ends in desc win, the data's finite min/max
// fill in the rest. With both ends explicit nothing is read; otherwise one pass over the file (raw or
// gzip) with a few MiB of buffer. NaN/Inf are an error naming their count and the first voxel unless
// opts says zero|clamp, as in load_volume. `progress` (optional) gets the fraction of voxels read.
ValueRange scan_value_range(const VolumeDesc& desc, const LoadOptions& opts = {},
                            const std::function<void(double fraction)>& progress = {});

// Streams the volume in z-slabs of whole slices, at most max(max_slab_voxels, one slice) voxels
// each, normalised to [0,1] with range [lo, hi]: fn(z0, nz, values) gets slices [z0, z0 + nz),
// x fastest. With the range load_volume(desc) finds (= scan_value_range(desc)) the concatenated
// slabs equal load_volume's data bit for bit, float data included: load_volume rounds v - pivot
// to float (pivot = an explicit range end of desc, else the first finite sample) before mapping
// it in double, and this does the same with the same pivot. Memory: one slab of floats plus a
// read buffer of at most 8 MiB (HDF5/NetCDF: plus the ~16 MiB of whole slices SampleStream reads). A file shorter than desc says is an error; so are NaN/Inf under
// NonFinitePolicy::Error (reported once the pass is complete, with load_volume's message; fn is
// not called again from the first slab that holds one).
void for_each_slab(const VolumeDesc& desc, double lo, double hi, const LoadOptions& opts, int64_t max_slab_voxels,
                   const std::function<void(int64_t z0, int64_t nz, const float* normalised)>& fn);


// How to read a volume file: the overrides of the CLI's --dims --dtype --endian --offset --timestep
// --range (a plain raw file needs dims and dtype) and its --nan policy.
struct VolumeOpenOptions {
  RawOptions raw;
  LoadOptions load;
};

// Opens a JSON sidecar, an instantvnr scene, NRRD/NHDR (raw or gzip) or a raw file (one timestep of a
// series with raw.timestep): describe_volume + load_volume. Bad input fails with one vnr::Error.
Volume open_volume(const std::string& path, const VolumeOpenOptions& options = {});
// What open_volume would read, without reading the data (dims, dtype, range overrides, timesteps).
VolumeDesc describe_volume_file(const std::string& path, const VolumeOpenOptions& options = {});
// Whether `path` names an HDF5 or NetCDF dataset (FILE.h5:/DATASET, FILE.nc:VARIABLE), or is such a file
// itself: what `vnr info` reads as a volume rather than a model.
bool is_dataset_path(const std::string& path);

// A volume from a caller's values (original units, x fastest, dims.count() of them): normalised
// exactly as open_volume normalises a float32 file holding the same values. `range` overrides the
// data's finite min/max (either end may be given); NaN/Inf follow policy (default: an error).
Volume volume_from_array(const float* values, Int3 dims, std::optional<double> range_lo = {},
                         std::optional<double> range_hi = {}, NonFinitePolicy policy = NonFinitePolicy::Error);
// The same for `dims.count()` samples of `dtype` at `samples` (x fastest; byte-swapped first when
// big_endian differs from the machine's): converted and normalised exactly as open_volume reads a raw
// file of that dtype, which the volume records as its source dtype.
Volume volume_from_samples(const void* samples, DType dtype, Int3 dims, bool big_endian = false,
                           std::optional<double> range_lo = {}, std::optional<double> range_hi = {},
                           NonFinitePolicy policy = NonFinitePolicy::Error);

// The volume's value at normalised coordinates (x, y, z) in [0, 1)^3: cell-centred trilinear
// (docs/semantics.md B.2), in normalised units. Batched callers should take view_of(v) once.
inline float volume_value(const Volume& v, float x, float y, float z) { return grid_lookup(view_of(v), x, y, z); }

}  // namespace vnr
