#pragma once
// Writing volumes: VolumeWriter streams one to disk in z-slabs (raw + sidecar, or NRRD), the byte-level
// pieces the MPI layer places itself, and the procedural volumes of demos, tests and benchmarks.
#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>
#include <type_traits>
#include <string>
#include <vector>
#include "vnr/fileio.h"
#include "vnr/math.h"
#include "vnr/volume.h"

namespace vnr {

// A value in original units as an output dtype stores it (VolumeWriter, `vnr decode`, the Python
// module's decode): integers rounded to nearest and clamped to the type, NaN -> 0.
template <typename T>
T to_stored_value(float v) {
  if constexpr (std::is_integral_v<T>) {
    const double r = std::isnan(v) ? 0.0 : std::nearbyint(double(v));
    return T(std::clamp(r, double(std::numeric_limits<T>::lowest()), double(std::numeric_limits<T>::max())));
  } else {
    return T(v);
  }
}

// Streams a volume to disk one z-slab at a time, so outputs larger than memory never need a full
// copy. The format follows the extension of `path`:
//   *.nrrd -> NRRD (raw encoding, little endian, "spacings" from spacing);
//   else   -> raw file at `path` plus a JSON sidecar "<path without extension>.json"
//             ({"file","dims","dtype","byte_order":"little","spacing","value_range"}), the same
//             sidecar format vnr reads. Without an explicit value_range
//             the sidecar gets the exact min/max of the stored values.
// Values are given as float in original units and converted to `dtype` (integers: rounded to
// nearest and clamped to the type's range). Both files are written atomically on commit().
class VolumeWriter {
public:
  VolumeWriter(const std::string& path, Int3 dims, DType dtype, Vec3f spacing = {1, 1, 1},
               std::optional<std::pair<double, double>> value_range = std::nullopt);
  ~VolumeWriter();
  // Appends `n_slices` complete z-slices (dims.x*dims.y*n_slices values).
  void write_slices(const float* values, int64_t n_slices);
  void commit();  // error if fewer than dims.z slices were written
  std::string sidecar_path() const;  // "" for NRRD

private:
  std::string path_;
  Int3 dims_;
  DType dtype_;
  Vec3f spacing_;
  std::optional<std::pair<double, double>> range_;
  int64_t slices_written_ = 0;
  double seen_lo_ = 1e308, seen_hi_ = -1e308;  // finite min/max of the stored values (sidecar range)
  std::unique_ptr<AtomicFile> file_;
};

// What VolumeWriter writes, for writers that place the bytes themselves (the MPI layer's parallel
// decode): the NRRD header ("" for raw output), the values converted to dtype's little-endian bytes
// (returns the finite min/max stored, lo > hi when none), and the raw sidecar's text.
std::string volume_file_header(const std::string& path, Int3 dims, DType dtype, Vec3f spacing);
std::pair<double, double> store_values(DType dtype, const float* values, int64_t n, unsigned char* out);
std::string raw_sidecar_text(const std::string& path, Int3 dims, DType dtype, Vec3f spacing,
                             std::optional<std::pair<double, double>> value_range);

// The files a VolumeWriter for `path` creates (the data file, and the sidecar for raw output).
std::vector<std::string> volume_output_files(const std::string& path);

// Procedural volumes for demos, tests and benchmarks, streamed to disk (raw + sidecar).
//   marschner-lobb: the Marschner-Lobb test signal (alpha 0.25, f_M 6) on [-1,1]^3, float32;
//   noise: multi-scale value noise (6 octaves), float32, deterministic for a seed.
// `out_json` is the sidecar path; the raw file is written beside it with extension .raw.
void synth_volume(const std::string& kind, Int3 dims, const std::string& out_json, uint64_t seed = 1);
// The files synth_volume(out_json) writes: the .raw data and the sidecar; error unless out_json ends in .json.
std::vector<std::string> synth_output_files(const std::string& out_json);
// The same fields evaluated at one point u in [0,1]^3 (for tests and analytic checks).
float synth_value(const std::string& kind, float ux, float uy, float uz, uint64_t seed = 1);

// A smoothly evolving series of `timesteps` frames of the same fields: timestep t is the field
// drifted by t * (0.02, 0.015, 0.01) of the volume's extent (f_t(u) = f(u - t v); t = 0 is
// synth_volume's volume), float32. Written as one 4-D sidecar (out_json; "<out>.raw" holds the
// frames one after another, "dims": [x, y, z, T]) or, with file_list, as a file-list sidecar
// naming one raw file per timestep ("<out>_t0000.raw", ...). The sidecar's value_range is the
// min/max over all timesteps, so every timestep normalises alike. Deterministic for a seed; files
// written atomically, the sidecar last.
void synth_series(const std::string& kind, Int3 dims, int timesteps, const std::string& out_json, uint64_t seed = 1,
                  bool file_list = false);
// The files synth_series writes (data files, then the sidecar).
std::vector<std::string> synth_series_output_files(const std::string& out_json, int timesteps, bool file_list);
// Timestep t of the series at one point (bit-identical to the stored voxel values at voxel centres).
float synth_series_value(const std::string& kind, int timestep, float ux, float uy, float uz, uint64_t seed = 1);

}  // namespace vnr
