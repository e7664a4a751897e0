#pragma once
// Random access to an uncompressed volume file without loading it: the out-of-core and
// memory-mapped training samplers (paper, "Out-of-Core Sampling") and sampled evaluation read
// through these. Values are normalised exactly as load_volume normalises them (docs/semantics.md B.1), bit
// for bit: with the same pivot (an explicit range end of the description, else the first finite
// sample of the timestep, read at construction) and the same arithmetic (sample_io.h).
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <sys/types.h>
#include "vnr/core/brick_box.h"
#include "vnr/volume/sample_io.h"
#include "vnr/volume/volume.h"

namespace vnr {

// Fails unless desc can be read at random offsets (raw encoding, or an HDF5/NetCDF dataset, read as
// hyperslabs); `what` names the reader in the message, `alternative` (optional) says what to do
// instead. RawVolumeFile checks this first.
void require_random_access(const VolumeDesc& desc, const std::string& what, const std::string& alternative = "");
// Fails unless desc's voxels are plain bytes in a file (raw encoding), as a memory map needs.
void require_raw_bytes(const VolumeDesc& desc, const std::string& what, const std::string& alternative = "");

// pread access to the voxels of one timestep of a raw-encoded volume (or hyperslab reads of an
// HDF5/NetCDF dataset: "file offsets" are then offsets into the timestep's samples, and a box is
// one hyperslab). Thread-safe: any number of threads may read at once (dataset reads take turns).
// Reads never leave [offset, offset + frame), and a file that shrinks gives a clear error instead
// of garbage.
class RawVolumeFile {
public:
  // Normalises with range [lo, hi]. Compressed data is refused with one line naming `what` (what
  // the voxels are read for) and, if not empty, `alternative` (what to do instead).
  RawVolumeFile(const VolumeDesc& desc, double lo, double hi, NonFinitePolicy policy,
                const std::string& what = "out-of-core sampling", const std::string& alternative = "");
  ~RawVolumeFile();
  RawVolumeFile(const RawVolumeFile&) = delete;
  RawVolumeFile& operator=(const RawVolumeFile&) = delete;

  Int3 dims() const { return desc_.dims; }
  const VolumeDesc& desc() const { return desc_; }
  uint64_t frame_bytes() const { return frame_bytes_; }
  int64_t voxel_count() const { return int64_t(desc_.dims.count()); }

  // Normalised voxels of the box [origin, origin + size) (x fastest) into out. Indices outside the
  // volume read the nearest edge voxel (clamp-to-edge, as the trilinear lookup does), which is
  // how ghost layers at the volume's border are filled. `scratch` holds at least
  // scratch_bytes(size) bytes. NaN/Inf under NonFinitePolicy::Error: an error naming the voxel.
  // Consecutive rows of a z-slice are read together when the file's rows are short (rows_per_read).
  void read_box(Int3 origin, Int3 size, float* out, unsigned char* scratch) const;
  // The same with the clamp at the faces of `clamp_to` (a non-empty box inside the volume) instead of
  // the volume's: only voxels inside it are read, as if it were the whole volume (a brick's region).
  void read_box(Int3 origin, Int3 size, float* out, unsigned char* scratch, const Box3& clamp_to) const;
  size_t scratch_bytes(Int3 box) const;
  int64_t rows_per_read(int64_t box_ny) const;

  // out[i] = normalised value of voxel voxel_index[i] (x + nx * (y + ny * z)), any order, repeats
  // allowed; an index outside the volume is an error. Nearby voxels are read together. NaN/Inf
  // under NonFinitePolicy::Error: an error naming the voxel.
  void read_voxels(const int64_t* voxel_index, int64_t n, float* out) const;

  // Fails with a clear message if the file disappeared, was replaced or changed size since it
  // was opened. Cheap (one stat); called once per training step.
  void check_unchanged() const;

  // Bytes read by read_box and read_voxels so far, and the lowest and highest file offsets they
  // read (inside the timestep's bytes).
  uint64_t bytes_read() const { return bytes_read_.load(std::memory_order_relaxed); }
  uint64_t min_read_begin() const { return min_read_begin_.load(std::memory_order_relaxed); }
  uint64_t max_read_end() const { return max_read_end_.load(std::memory_order_relaxed); }

private:
  void read_bytes(unsigned char* dst, size_t bytes, uint64_t file_offset) const;
  void open_dataset(double lo, double hi);
  void read_dataset_box(Int3 origin, Int3 size, float* out, const Box3& clamp_to) const;
  void count_read(size_t bytes, uint64_t file_offset) const;
  VolumeDesc desc_;
  std::unique_ptr<detail::DatasetReader> dataset_;  // HDF5/NetCDF sources
  detail::PivotNormaliser norm_;
  NonFinitePolicy policy_;
  int fd_ = -1;
  size_t esize_;
  bool swap_;
  uint64_t frame_bytes_, file_bytes_;
  dev_t dev_;
  ino_t ino_;
  mutable std::atomic<uint64_t> bytes_read_{0}, max_read_end_{0}, min_read_begin_{UINT64_MAX};
};

// The whole data region of one timestep memory-mapped read-only; trilinear lookups convert and
// normalise the 8 neighbours on the fly. The baseline the paper compares out-of-core sampling with:
// every lookup may fault pages in from disk.
class MappedVolume {
public:
  MappedVolume(const VolumeDesc& desc, double lo, double hi, NonFinitePolicy policy);
  ~MappedVolume();
  MappedVolume(const MappedVolume&) = delete;
  MappedVolume& operator=(const MappedVolume&) = delete;
  Int3 dims() const { return desc_.dims; }
  // grid_lookup semantics over the mapped data, for n points (SoA).
  void lookup(const float* x, const float* y, const float* z, int64_t n, float* out) const;
  void check_unchanged() const;

private:
  VolumeDesc desc_;
  detail::PivotNormaliser norm_;
  bool swap_;
  const unsigned char* base_ = nullptr;  // first voxel of the timestep
  void* map_ = nullptr;
  size_t map_bytes_ = 0;
  uint64_t file_bytes_;
  dev_t dev_;
  ino_t ino_;
};

}  // namespace vnr
