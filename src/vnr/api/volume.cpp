// vnr::Volume's constructors: files through the volume layer, arrays with load_volume's normalisation.
#include "vnr/volume.h"
#include <new>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/volume/dataset.h"
#include "vnr/volume/sample_io.h"

namespace vnr {

VolumeDesc describe_volume_file(const std::string& path, const VolumeOpenOptions& options) {
  return describe_volume(path, options.raw);
}

Volume open_volume(const std::string& path, const VolumeOpenOptions& options) {
  return load_volume(describe_volume(path, options.raw), options.load);
}

// load_volume's two steps (keep relative to the pivot, then map with the resolved range) over the
// caller's samples, so an array and a raw file of the same values give the same bits.
Volume volume_from_samples(const void* samples, DType dtype, Int3 dims, bool big_endian,
                           std::optional<double> range_lo, std::optional<double> range_hi, NonFinitePolicy policy) {
  using namespace detail;
  VolumeDesc desc;
  desc.path = "array";
  desc.dims = dims;
  desc.dtype = dtype;
  desc.big_endian = big_endian;
  desc.range_lo = range_lo;
  desc.range_hi = range_hi;
  check_dims(desc);
  if (!samples) fail("volume_from_samples: no values given for {}x{}x{} voxels", dims.x, dims.y, dims.z);
  const int64_t n = int64_t(dims.count());
  Volume vol;
  vol.dims = dims;
  vol.source_dtype = dtype;
  try {
    vol.data.resize(size_t(n));
  } catch (const std::bad_alloc&) {
    fail("cannot allocate {:.1f} GiB for a {}x{}x{} volume", double(n) * 4 / (1 << 30), dims.x, dims.y, dims.z);
  }
  const auto* bytes = static_cast<const unsigned char*>(samples);
  const bool swap = needs_swap(desc);
  double pivot = 0;
  Tally t;
  with_sample_type(dtype, [&](auto tag) {
    using T = typename decltype(tag)::type;
    if (!pivot_from_desc(desc, &pivot)) find_pivot<T>(bytes, n, swap, &pivot);
    t = convert<T>(bytes, n, 0, swap, pivot, vol.data.data());
  });
  if (t.nonfinite > 0 && policy == NonFinitePolicy::Error) nonfinite_error(desc, t.nonfinite, t.first_nonfinite);
  const ValueRange r = resolve_range(desc, t);
  vol.lo = r.lo;
  vol.hi = r.hi;
  map_in_place(PivotNormaliser(pivot, r.lo, r.hi, policy), vol.data.data(), n);
  return vol;
}

Volume volume_from_array(const float* values, Int3 dims, std::optional<double> range_lo,
                         std::optional<double> range_hi, NonFinitePolicy policy) {
  return volume_from_samples(values, DType::Float32, dims, false, range_lo, range_hi, policy);
}

bool is_dataset_path(const std::string& path) {
  if (file_exists(path)) return !detail::dataset_encoding_of_extension(extension_of(path)).empty();
  return path.find(':') != std::string::npos;
}

}  // namespace vnr
