#pragma once
#include <cstdint>
#include <optional>
#include <string>
#include <vector>
#include "vnr/core/dtype.h"
#include "vnr/core/hd.h"
#include "vnr/core/math.h"
#include "vnr/core/memory.h"

namespace vnr {

// How NaN / Inf in float data are treated when loading. Default: error.
enum class NonFinitePolicy { Error, Zero, Clamp };

// Where a volume comes from, everything needed to read it. Produced by describe_volume().
struct VolumeDesc {
  std::string path;          // the raw data file (or the .nrrd file for NRRD)
  Int3 dims;                 // voxels per axis, x fastest
  DType dtype = DType::UInt8;
  bool big_endian = false;
  uint64_t offset = 0;       // bytes to skip before the first voxel (after timestep selection)
  std::string encoding = "raw";  // "raw" or "gzip" (NRRD)
  uint64_t gzip_start = 0;   // gzip: where the compressed stream starts in `path`; `offset` then
                             // counts decompressed bytes
  int n_timesteps = 1;       // a 4th sidecar dim
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
// or gzip), and plain raw files (with RawOptions). Validates everything it can without reading
// the data: file size vs dims x dtype (message states expected and actual bytes), zero or
// overflowing dims, unknown dtype, unreadable file.
VolumeDesc describe_volume(const std::string& path, const RawOptions& opts = {});

// A volume in memory, normalised to [0,1] with u = clamp((v - lo)/(hi - lo), 0, 1) (compat.md B.1).
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

// POD view of a normalised grid; what per-sample code (training targets, ground-truth rendering) reads.
struct GridView {
  const float* data = nullptr;
  int32_t nx = 0, ny = 0, nz = 0;
};
inline GridView view_of(const Volume& v) {
  return GridView{v.data.data(), int32_t(v.dims.x), int32_t(v.dims.y), int32_t(v.dims.z)};
}

// Cell-centred, clamp-to-edge trilinear interpolation at u in [0,1)^3 (compat.md B.2) over any
// voxel accessor at(x, y, z) with global indices: p = u*N - 0.5 clamped to [0, N-1] per axis;
// trilinear between floor(p) and min(floor(p)+1, N-1). The in-memory grid, out-of-core blocks and
// memory-mapped files all go through this one function, so they agree bit for bit.
template <typename At>
VNR_HD VNR_INLINE float cell_centred_trilinear(int32_t nx, int32_t ny, int32_t nz, float ux, float uy, float uz,
                                               const At& at) {
  float p[3] = {ux * float(nx) - 0.5f, uy * float(ny) - 0.5f, uz * float(nz) - 0.5f};
  int32_t n[3] = {nx, ny, nz};
  int32_t i0[3], i1[3];
  float t[3];
  for (int d = 0; d < 3; ++d) {
    float hi = float(n[d] - 1);
    float q = p[d] < 0.f ? 0.f : (p[d] > hi ? hi : p[d]);
    float fl = floorf(q);
    i0[d] = int32_t(fl);
    i1[d] = i0[d] + 1 < n[d] ? i0[d] + 1 : n[d] - 1;
    t[d] = q - fl;
  }
  float c00 = at(i0[0], i0[1], i0[2]) * (1 - t[0]) + at(i1[0], i0[1], i0[2]) * t[0];
  float c10 = at(i0[0], i1[1], i0[2]) * (1 - t[0]) + at(i1[0], i1[1], i0[2]) * t[0];
  float c01 = at(i0[0], i0[1], i1[2]) * (1 - t[0]) + at(i1[0], i0[1], i1[2]) * t[0];
  float c11 = at(i0[0], i1[1], i1[2]) * (1 - t[0]) + at(i1[0], i1[1], i1[2]) * t[0];
  float c0 = c00 * (1 - t[1]) + c10 * t[1];
  float c1 = c01 * (1 - t[1]) + c11 * t[1];
  return c0 * (1 - t[2]) + c1 * t[2];
}

// The lookup on an in-memory normalised grid.
VNR_HD VNR_INLINE float grid_lookup(const GridView& g, float ux, float uy, float uz) {
  const int64_t sy = g.nx, sz = int64_t(g.nx) * g.ny;
  return cell_centred_trilinear(g.nx, g.ny, g.nz, ux, uy, uz,
                                [&](int32_t x, int32_t y, int32_t z) { return g.data[x + y * sy + z * sz]; });
}

// The same lookup for n points (SoA), vectorised with gathers; bit-identical to grid_lookup.
void grid_lookup_batch(const GridView& g, const float* x, const float* y, const float* z, int64_t n, float* out);

}  // namespace vnr
