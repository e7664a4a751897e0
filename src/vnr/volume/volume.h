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

// POD view of a normalised grid; what per-sample code (training targets, ground-truth rendering) reads.
struct GridView {
  const float* data = nullptr;
  int32_t nx = 0, ny = 0, nz = 0;
};
inline GridView view_of(const Volume& v) {
  return GridView{v.data.data(), int32_t(v.dims.x), int32_t(v.dims.y), int32_t(v.dims.z)};
}

// Cell-centred, clamp-to-edge trilinear interpolation at u in [0,1)^3 (docs/semantics.md B.2) over any
// voxel accessor at(x, y, z) with global indices: p = u*N - 0.5 clamped to [0, N-1] per axis;
// trilinear between floor(p) and min(floor(p)+1, N-1). The in-memory grid, out-of-core blocks and
// memory-mapped files all go through this one function, so they agree bit for bit.
// One axis of it: the two voxel indices and the weight of the upper one.
struct CellAxis {
  int32_t i0, i1;
  float t;
};
VNR_HD VNR_INLINE CellAxis cell_axis(float u, int32_t n) {
  const float p = u * float(n) - 0.5f, hi = float(n - 1);
  const float q = !(p >= 0.f) ? 0.f : (p > hi ? hi : p);  // NaN -> 0
  const int32_t i0 = int32_t(q);  // q >= 0: truncation is floor, and far cheaper than floorf without SSE4.1
  return CellAxis{i0, i0 + 1 < n ? i0 + 1 : n - 1, q - float(i0)};
}
// Written out per axis (no arrays) so the compiler keeps everything in registers: the lookup is the
// innermost work of grid rendering (about half the instructions of a grid ray-marching sample).
// The interpolation itself, over the 8 corner values v[x + 2y + 4z] (x = 0: i0, 1: i1).
VNR_HD VNR_INLINE float trilinear_corners(const CellAxis& x, const CellAxis& y, const CellAxis& z, const float* v) {
  float c00 = v[0] * (1 - x.t) + v[1] * x.t;
  float c10 = v[2] * (1 - x.t) + v[3] * x.t;
  float c01 = v[4] * (1 - x.t) + v[5] * x.t;
  float c11 = v[6] * (1 - x.t) + v[7] * x.t;
  float c0 = c00 * (1 - y.t) + c10 * y.t;
  float c1 = c01 * (1 - y.t) + c11 * y.t;
  return c0 * (1 - z.t) + c1 * z.t;
}
template <typename At>
VNR_HD VNR_INLINE float cell_centred_trilinear(int32_t nx, int32_t ny, int32_t nz, float ux, float uy, float uz,
                                               const At& at) {
  const CellAxis x = cell_axis(ux, nx), y = cell_axis(uy, ny), z = cell_axis(uz, nz);
  const float v[8] = {at(x.i0, y.i0, z.i0), at(x.i1, y.i0, z.i0), at(x.i0, y.i1, z.i0), at(x.i1, y.i1, z.i0),
                      at(x.i0, y.i0, z.i1), at(x.i1, y.i0, z.i1), at(x.i0, y.i1, z.i1), at(x.i1, y.i1, z.i1)};
  return trilinear_corners(x, y, z, v);
}

// The lookup on an in-memory normalised grid.
// Same arithmetic as cell_centred_trilinear; the corners are addressed from one base offset (a
// third fewer instructions per grid-rendering sample than eight independent index computations).
VNR_HD VNR_INLINE float grid_lookup(const GridView& g, float ux, float uy, float uz) {
  const CellAxis x = cell_axis(ux, g.nx), y = cell_axis(uy, g.ny), z = cell_axis(uz, g.nz);
  const int64_t sy = g.nx, sz = int64_t(g.nx) * g.ny;
  const float* b = g.data + (x.i0 + y.i0 * sy + z.i0 * sz);
  const int64_t dx = x.i1 - x.i0, dy = (y.i1 - y.i0) * sy, dz = (z.i1 - z.i0) * sz;
  const float v[8] = {b[0], b[dx], b[dy], b[dx + dy], b[dz], b[dx + dz], b[dy + dz], b[dx + dy + dz]};
  return trilinear_corners(x, y, z, v);
}

// Normalised coordinates of the centre of voxel v (x + dims.x * (y + dims.y * z)): (i + 0.5) / n per
// axis, the one expression every decoder (CPU, GPU, whole slices or chosen voxels) uses.
VNR_HD VNR_INLINE void voxel_centre(Int3 dims, int64_t v, float* x, float* y, float* z) {
  const int64_t ix = v % dims.x, iy = (v / dims.x) % dims.y, iz = v / (dims.x * dims.y);
  *x = (float(ix) + 0.5f) / float(dims.x);
  *y = (float(iy) + 0.5f) / float(dims.y);
  *z = (float(iz) + 0.5f) / float(dims.z);
}

// SIMD versions of the lookup gather with 32-bit indices: volumes below 2^31 voxels.
inline bool grid_fits_gather_indices(const GridView& g) {
  return uint64_t(g.nx) * uint64_t(g.ny) * uint64_t(g.nz) < (uint64_t(1) << 31);
}
// The same lookup for n points (SoA), vectorised with gathers; bit-identical to grid_lookup.
void grid_lookup_batch(const GridView& g, const float* x, const float* y, const float* z, int64_t n, float* out);

}  // namespace vnr
