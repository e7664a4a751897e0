// load_volume: one streaming pass over the file (raw or gzip) that converts every sample and keeps
// it as float(v - pivot), then normalisation in place once the range is known (docs/semantics.md B.1;
// both steps: PivotNormaliser, sample_io.h).
#include <algorithm>
#include <new>
#include "vnr/error.h"
#include "vnr/units.h"
#include "vnr/volume/sample_io.h"
#include "vnr/volume/volume.h"

namespace vnr {

using namespace detail;

namespace {

// A header may claim any size: refuse what cannot fit before allocating, naming the sizes, rather
// than letting the allocation fail late or the machine swap.
void check_in_core_fits(const VolumeDesc& desc, uint64_t n) {
  const double bytes = double(n) * sizeof(float);
  const uint64_t available = available_memory_bytes();
  if (bytes <= double(available)) return;
  fail("'{}': dims {}x{}x{} = {:.3g} voxels x {} bytes = {} exceeds the memory available ({}); use the out-of-core "
       "sampler (--sampler outofcore)",
       desc.path, desc.dims.x, desc.dims.y, desc.dims.z, double(n), sizeof(float), human_bytes(bytes),
       human_bytes(double(available)));
}

}  // namespace

Volume load_volume(const VolumeDesc& desc, const LoadOptions& opts) {
  check_dims(desc);
  const Int3 d = desc.dims;
  const uint64_t n = d.count();
  const size_t esize = dtype_size(desc.dtype);

  check_in_core_fits(desc, n);
  Volume vol;
  vol.dims = d;
  vol.source_dtype = desc.dtype;
  vol.spacing = desc.spacing;
  try {
    vol.data.resize(n);
  } catch (const std::bad_alloc&) {
    fail("cannot allocate {:.1f} GiB for '{}' ({} voxels)", double(n) * 4 / (1 << 30), desc.path, n);
  }

  const bool swap = needs_swap(desc);
  double pivot = 0;
  bool pivot_set = pivot_from_desc(desc, &pivot);
  Tally acc;
  const uint64_t chunk = uint64_t(1) << 22;
  std::vector<unsigned char> buf(size_t(std::min(n, chunk) * esize));
  SampleStream in(desc);
  for (uint64_t i0 = 0; i0 < n; i0 += chunk) {
    const uint64_t m = std::min(chunk, n - i0);
    in.read(buf.data(), m * esize);
    with_sample_type(desc.dtype, [&](auto tag) {
      using T = typename decltype(tag)::type;
      if (!pivot_set) pivot_set = find_pivot<T>(buf.data(), int64_t(m), swap, &pivot);
      acc.merge(convert<T>(buf.data(), int64_t(m), i0, swap, pivot, vol.data.data() + i0));
    });
  }
  in.finish();
  if (acc.nonfinite > 0 && opts.non_finite == NonFinitePolicy::Error)
    nonfinite_error(desc, acc.nonfinite, acc.first_nonfinite);

  const ValueRange r = resolve_range(desc, acc);
  vol.lo = r.lo;
  vol.hi = r.hi;
  map_in_place(PivotNormaliser(pivot, r.lo, r.hi, opts.non_finite), vol.data.data(), int64_t(n));
  return vol;
}

}  // namespace vnr
