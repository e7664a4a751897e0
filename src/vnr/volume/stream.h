#pragma once
// Reading volumes that need not fit in memory: the value range from one streaming pass, the
// normalised data in z-slabs, and normalised values at arbitrary voxels. Every function normalises
// exactly as load_volume does (compat.md B.1), bit for bit, so a streamed evaluation sees the same
// numbers as an in-memory one.
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
// read buffer of at most 8 MiB. A file shorter than desc says is an error; so are NaN/Inf under
// NonFinitePolicy::Error (reported once the pass is complete, with load_volume's message; fn is
// not called again from the first slab that holds one).
void for_each_slab(const VolumeDesc& desc, double lo, double hi, const LoadOptions& opts, int64_t max_slab_voxels,
                   const std::function<void(int64_t z0, int64_t nz, const float* normalised)>& fn);

// Normalised values at arbitrary voxels of an uncompressed volume, read with pread (random access;
// nothing is loaded). Values equal load_volume's data for the same range, bit for bit. gzip data
// cannot be read at random offsets: the constructor refuses it with a one-line error that says so
// and what to do instead. read() is safe to call from several threads.
class VoxelReader {
public:
  VoxelReader(const VolumeDesc& desc, double lo, double hi, const LoadOptions& opts = {});
  ~VoxelReader();
  VoxelReader(const VoxelReader&) = delete;
  VoxelReader& operator=(const VoxelReader&) = delete;

  // out[i] = normalised value of voxel voxel_index[i] (x + nx * (y + ny * z)), any order, repeats
  // allowed. Nearby voxels are read together. NaN/Inf under NonFinitePolicy::Error: an error naming
  // the voxel.
  void read(const int64_t* voxel_index, int64_t n, float* out) const;
  int64_t voxel_count() const { return n_voxels_; }

private:
  VolumeDesc desc_;
  LoadOptions opts_;
  int fd_ = -1;
  int64_t n_voxels_ = 0;
  double pivot_ = 0, shift_ = 0, inv_ = 0;
};

}  // namespace vnr
