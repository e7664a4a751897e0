#pragma once
#include <cstdint>
#include <optional>
#include <string>
#include <vector>
#include "vnr/dtype.h"
#include "vnr/core/grid_view.h"
#include "vnr/hd.h"
#include "vnr/math.h"
#include "vnr/core/memory.h"

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

// The grid view of a loaded volume (core/grid_view.h: GridView, grid_lookup).
inline GridView view_of(const Volume& v) {
  return GridView{v.data.data(), int32_t(v.dims.x), int32_t(v.dims.y), int32_t(v.dims.z)};
}

// Normalised coordinates of the centre of voxel v (x + dims.x * (y + dims.y * z)): (i + 0.5) / n per
// axis, the one expression every decoder (CPU, GPU, whole slices or chosen voxels) uses.
VNR_HD VNR_INLINE void voxel_centre(Int3 dims, int64_t v, float* x, float* y, float* z) {
  const int64_t ix = v % dims.x, iy = (v / dims.x) % dims.y, iz = v / (dims.x * dims.y);
  *x = (float(ix) + 0.5f) / float(dims.x);
  *y = (float(iy) + 0.5f) / float(dims.y);
  *z = (float(iz) + 0.5f) / float(dims.z);
}

// grid_lookup (core/grid_view.h) for n points (SoA), vectorised with gathers; bit-identical to it.
void grid_lookup_batch(const GridView& g, const float* x, const float* y, const float* z, int64_t n, float* out);

}  // namespace vnr
