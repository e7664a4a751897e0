#pragma once
// Random access to an uncompressed volume file without loading it: the out-of-core and
// memory-mapped training samplers read through these (paper, "Out-of-Core Sampling").
#include <atomic>
#include <cstdint>
#include <string>
#include <sys/types.h>
#include "vnr/volume/volume.h"

namespace vnr {

// Normalisation of one source value (compat.md B.1): u = clamp((v - lo) / (hi - lo), 0, 1);
// a constant volume maps to 0. Non-finite values follow the policy (Error is the caller's check).
struct Normaliser {
  double lo = 0, inv = 0;  // inv = 1 / (hi - lo), or 0 for a constant volume
  bool clamp_inf = false;
  Normaliser() = default;
  Normaliser(double lo_, double hi_, NonFinitePolicy p)
      : lo(lo_), inv(hi_ > lo_ ? 1.0 / (hi_ - lo_) : 0.0), clamp_inf(p == NonFinitePolicy::Clamp) {}
  float operator()(double v) const {
    if (!(v - v == 0)) return (clamp_inf && v > 0 && inv > 0) ? 1.f : 0.f;  // NaN, -Inf -> lo; +Inf -> per policy
    double u = (v - lo) * inv;
    return u <= 0 ? 0.f : (u >= 1 ? 1.f : float(u));
  }
};

// pread access to the voxels of one timestep of a raw-encoded volume. Thread-safe: any number of
// threads may read at once. Every read is checked against the file's size, so a file that
// shrinks gives a clear error instead of garbage, and reads never leave [offset, offset + frame).
class RawVolumeFile {
public:
  // `desc` must be raw-encoded (a gzip NRRD gets an error suggesting `vnr convert`).
  RawVolumeFile(const VolumeDesc& desc, double lo, double hi, NonFinitePolicy policy);
  ~RawVolumeFile();
  RawVolumeFile(const RawVolumeFile&) = delete;
  RawVolumeFile& operator=(const RawVolumeFile&) = delete;

  Int3 dims() const { return desc_.dims; }
  const VolumeDesc& desc() const { return desc_; }
  const Normaliser& normaliser() const { return norm_; }
  uint64_t frame_bytes() const { return frame_bytes_; }

  // Normalised voxels of the box [origin, origin + size) (x fastest) into out. Indices outside the
  // volume read the nearest edge voxel (clamp-to-edge, as the trilinear lookup does), which is
  // how ghost layers at the volume's border are filled. `scratch` holds at least
  // scratch_bytes(size.x) bytes.
  void read_box(Int3 origin, Int3 size, float* out, unsigned char* scratch) const;
  size_t scratch_bytes(int64_t nx) const { return size_t(nx) * esize_; }

  // Fails with a clear message if the file disappeared, was replaced or changed size since it
  // was opened. Cheap (one stat); called once per training step.
  void check_unchanged() const;

  uint64_t bytes_read() const { return bytes_read_.load(std::memory_order_relaxed); }
  // The lowest and highest file offsets read so far (reads stay inside the timestep's bytes).
  uint64_t min_read_begin() const { return min_read_begin_.load(std::memory_order_relaxed); }
  uint64_t max_read_end() const { return max_read_end_.load(std::memory_order_relaxed); }

private:
  void pread_exact(unsigned char* dst, size_t bytes, uint64_t file_offset) const;
  VolumeDesc desc_;
  Normaliser norm_;
  NonFinitePolicy policy_;
  int fd_ = -1;
  size_t esize_;
  bool swap_;
  uint64_t frame_bytes_, file_bytes_;
  dev_t dev_;
  ino_t ino_;
  mutable std::atomic<uint64_t> bytes_read_{0}, max_read_end_{0}, min_read_begin_{UINT64_MAX};
};

// Converts n source elements of `dtype` (byte-swapped if `swap`) to normalised floats. Returns the
// index of the first non-finite value, or -1.
int64_t normalise_elements(DType dtype, bool swap, const unsigned char* src, int64_t n, const Normaliser& norm,
                           float* out);

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
  Normaliser norm_;
  bool swap_;
  const unsigned char* base_ = nullptr;  // first voxel of the timestep
  void* map_ = nullptr;
  size_t map_bytes_ = 0;
  uint64_t file_bytes_;
  dev_t dev_;
  ino_t ino_;
};

}  // namespace vnr
