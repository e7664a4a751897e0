#pragma once
// vnr::Volume: a scalar volume in memory, normalised to [0, 1] with its value range in original units
// (docs/semantics.md B.1). The type is the volume layer's struct (src/vnr/volume/volume.h): dims,
// source_dtype, the range [lo, hi], the normalised values `data` (x fastest) and view_of() -> GridView,
// the POD every per-sample lookup (grid_lookup) reads. This header adds the ways to make one.
#include <optional>
#include <string>
#include "vnr/volume/stream.h"
#include "vnr/volume/volume.h"

namespace vnr {

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
