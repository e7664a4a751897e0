#pragma once
// Streaming volumes that need not fit in memory: the value range from one pass, and the normalised
// data in z-slabs. Both normalise exactly as load_volume does (docs/semantics.md B.1), bit for bit, so a
// streamed evaluation sees the same numbers as an in-memory one. (Normalised values at arbitrary
// voxels: RawVolumeFile, raw_access.h.)
#include <cstdint>
#include <functional>
#include <string>
#include <vector>
#include "vnr/volume/volume.h"

namespace vnr {

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

}  // namespace vnr
