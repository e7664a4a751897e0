// The streaming readers of stream.h, and the pieces of sample_io.h that are not inline. Conversion
// and normalisation are load_volume's (sample_io.h), so the values are bit-identical to an
// in-memory load; tests/test_stream_eval.cpp checks this on every dtype.
#include "vnr/volume/stream.h"
#include <fcntl.h>
#include <unistd.h>
#include <zlib.h>
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <new>
#include "vnr/error.h"
#include "vnr/volume/dataset.h"
#include "vnr/volume/formats.h"
#include "vnr/volume/sample_io.h"

namespace vnr {

namespace detail {

void check_dims(const VolumeDesc& desc) {
  const Int3 d = desc.dims;
  if (d.x <= 0 || d.y <= 0 || d.z <= 0 || d.x > (1 << 30) || d.y > (1 << 30) || d.z > (1 << 30) ||
      d.count() > (uint64_t(1) << 40))
    fail("'{}': invalid dims {}", desc.path, dims_string(d));
}

void check_range(const VolumeDesc& desc, double lo, double hi) {
  if (!std::isfinite(lo) || !std::isfinite(hi)) fail("'{}': value range must be finite", desc.path);
  if (lo > hi) fail("'{}': invalid value range [{}, {}] (lo > hi)", desc.path, lo, hi);
}

ValueRange resolve_range(const VolumeDesc& desc, const Tally& t) {
  const bool any_finite = t.lo <= t.hi;
  double lo = desc.range_lo ? *desc.range_lo : (any_finite ? t.lo : (desc.range_hi ? *desc.range_hi : 0.0));
  double hi = desc.range_hi ? *desc.range_hi : (any_finite ? t.hi : lo);
  if (!std::isfinite(lo) || !std::isfinite(hi)) fail("'{}': value range must be finite", desc.path);
  if (desc.range_lo && desc.range_hi && lo > hi)
    fail("'{}': invalid value range [{}, {}] (lo > hi)", desc.path, lo, hi);
  if (hi < lo) hi = lo;
  return ValueRange{lo, hi};
}

void nonfinite_error(const VolumeDesc& desc, uint64_t count, uint64_t first) {
  const Int3 d = desc.dims;
  uint64_t xy = uint64_t(d.x) * uint64_t(d.y);
  fail("'{}' contains {} NaN/Inf values (first at voxel ({},{},{})); use --nan zero|clamp", desc.path, count,
       first % uint64_t(d.x), (first / uint64_t(d.x)) % uint64_t(d.y), first / xy);
}

void pread_exact(int fd, unsigned char* dst, size_t bytes, uint64_t at, const std::string& path) {
  for (size_t done = 0; done < bytes;) {
    ssize_t r = ::pread(fd, dst + done, bytes - done, off_t(at + done));
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) fail("cannot read '{}' at byte {}: {}", path, at + done, std::strerror(errno));
    if (r == 0)
      fail("'{}': unexpected end of file at byte {} (did the file change since it was described?)", path, at + done);
    done += size_t(r);
  }
}

// ---------------------------------------------------------------------------------------------
SampleStream::SampleStream(const VolumeDesc& desc) : desc_(desc) {
  frame_ = desc.dims.count() * dtype_size(desc.dtype);
  if (is_dataset_encoding(desc.encoding)) {
    dataset_ = open_dataset_reader(desc);
    return;
  }
  if (desc.encoding == "gzip") {
    int fd = ::open(desc.path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) fail("cannot open '{}': {}", desc.path, std::strerror(errno));
    if (::lseek(fd, off_t(desc.gzip_start), SEEK_SET) < 0) {
      ::close(fd);
      fail("cannot seek to byte {} in '{}'", desc.gzip_start, desc.path);
    }
    gz_ = gzdopen(fd, "rb");  // takes ownership of fd
    if (!gz_) {
      ::close(fd);
      fail("cannot open gzip stream in '{}'", desc.path);
    }
    gzbuffer(gz_, 1 << 18);
  } else {
    f_ = std::fopen(desc.path.c_str(), "rb");
    if (!f_) fail("cannot open '{}': {}", desc.path, std::strerror(errno));
    pos_ = desc.offset;
  }
  try {  // the destructor does not run when the constructor throws
    if (gz_) {
      std::vector<unsigned char> tmp(1 << 16);
      for (uint64_t skip = desc.offset; skip > 0;) {  // `offset` counts decompressed bytes
        uint64_t m = std::min<uint64_t>(skip, tmp.size());
        if (gz_read(tmp.data(), m) != m) gz_size_error();
        skip -= m;
      }
    } else if (fseeko(f_, off_t(desc.offset), SEEK_SET) != 0) {
      fail("cannot seek to byte {} in '{}'", desc.offset, desc.path);
    }
  } catch (...) {
    close();
    throw;
  }
}

SampleStream::~SampleStream() { close(); }

void SampleStream::read(unsigned char* dst, uint64_t bytes) {
  if (dataset_) return dataset_read(dst, bytes);
  if (gz_) {
    if (gz_read(dst, bytes) != bytes) gz_size_error();
    return;
  }
  size_t n = std::fread(dst, 1, size_t(bytes), f_);
  pos_ += n;
  if (n != bytes) {
    if (std::ferror(f_)) fail("cannot read '{}': {}", desc_.path, std::strerror(errno));
    fail("'{}': unexpected end of file at byte {} (did the file change since it was described?)", desc_.path, pos_);
  }
}

// Serves the bytes from a slab of whole z-slices, read as one hyperslab: a multiple of the chunks'
// z-extent (each chunk decompressed once) of about 16 MiB, at least one chunk layer.
void SampleStream::dataset_read(unsigned char* dst, uint64_t bytes) {
  const uint64_t slice = uint64_t(desc_.dims.x) * uint64_t(desc_.dims.y) * dtype_size(desc_.dtype);
  const uint64_t chunk_z = uint64_t(dataset_->chunk_slices());
  const uint64_t slab_slices = chunk_z * std::max<uint64_t>(1, (uint64_t(16) << 20) / (slice * chunk_z));
  while (bytes > 0) {
    if (pos_ >= slab_begin_ && pos_ < slab_end_) {
      const uint64_t m = std::min(bytes, slab_end_ - pos_);
      std::memcpy(dst, slab_.data() + (pos_ - slab_begin_), size_t(m));
      dst += m, pos_ += m, bytes -= m;
      continue;
    }
    const uint64_t z0 = pos_ / slice;
    if (z0 >= uint64_t(desc_.dims.z)) fail("'{}:{}': read past the last slice", desc_.path, desc_.dataset);
    const uint64_t k = std::min(slab_slices - z0 % slab_slices, uint64_t(desc_.dims.z) - z0);
    slab_.resize(size_t(k * slice));
    dataset_->read_box(Int3{0, 0, int64_t(z0)}, Int3{desc_.dims.x, desc_.dims.y, int64_t(k)}, slab_.data());
    slab_begin_ = z0 * slice;
    slab_end_ = slab_begin_ + k * slice;
  }
}

void SampleStream::finish() {
  if (gz_ && gz_drain() != gz_expected()) gz_size_error();
}

void SampleStream::close() {
  if (gz_) gzclose(gz_);
  if (f_) std::fclose(f_);
  gz_ = nullptr;
  f_ = nullptr;
}

uint64_t SampleStream::gz_read(unsigned char* dst, uint64_t bytes) {
  uint64_t done = 0;
  while (done < bytes) {
    unsigned want = unsigned(std::min<uint64_t>(bytes - done, 1u << 30));
    int r = gzread(gz_, dst + done, want);
    if (r < 0) {
      int code = 0;
      const char* msg = gzerror(gz_, &code);
      fail("'{}': corrupt gzip data after {} decompressed bytes ({})", desc_.path, gz_total_ + done,
           msg ? msg : "?");
    }
    if (r == 0) break;
    done += uint64_t(r);
  }
  gz_total_ += done;
  return done;
}

// Reads (and drops) the rest of the stream, for the size message.
uint64_t SampleStream::gz_drain() {
  std::vector<unsigned char> tmp(1 << 18);
  while (gz_read(tmp.data(), tmp.size()) == tmp.size()) {
  }
  return gz_total_;
}

// The decompressed size the description implies: the byte skip plus every timestep.
uint64_t SampleStream::gz_base() const { return desc_.offset - uint64_t(desc_.timestep) * frame_; }
uint64_t SampleStream::gz_expected() const { return gz_base() + uint64_t(desc_.n_timesteps) * frame_; }

void SampleStream::gz_size_error() {
  fail("'{}' decompresses to {} bytes, expected {} ({} {} + byte skip {})", desc_.path, gz_drain(), gz_expected(),
       dims_string(desc_.dims, desc_.n_timesteps), dtype_name(desc_.dtype), gz_base());
}

}  // namespace detail

using namespace detail;

// Voxels converted per read: at most 8 MiB of float64 input, whatever the volume size.
constexpr int64_t kChunkVoxels = int64_t(1) << 20;

ValueRange scan_value_range(const VolumeDesc& desc, const LoadOptions& opts,
                            const std::function<void(double)>& progress) {
  check_dims(desc);
  Tally acc;
  if (!(desc.range_lo && desc.range_hi)) {  // both ends explicit: the data cannot change the range
    const uint64_t n = desc.dims.count();
    const size_t esize = dtype_size(desc.dtype);
    const bool swap = needs_swap(desc);
    std::vector<unsigned char> buf(size_t(std::min<uint64_t>(n, kChunkVoxels) * esize));
    SampleStream in(desc);
    for (uint64_t i0 = 0; i0 < n; i0 += kChunkVoxels) {
      const uint64_t m = std::min<uint64_t>(kChunkVoxels, n - i0);
      in.read(buf.data(), m * esize);
      with_sample_type(desc.dtype, [&](auto tag) {
        using T = typename decltype(tag)::type;
        acc.merge(convert<T>(buf.data(), int64_t(m), i0, swap, 0.0, nullptr));
      });
      if (progress) progress(double(i0 + m) / double(n));
    }
    in.finish();
    if (acc.nonfinite > 0 && opts.non_finite == NonFinitePolicy::Error)
      nonfinite_error(desc, acc.nonfinite, acc.first_nonfinite);
  }
  return resolve_range(desc, acc);
}

void for_each_slab(const VolumeDesc& desc, double lo, double hi, const LoadOptions& opts, int64_t max_slab_voxels,
                   const std::function<void(int64_t, int64_t, const float*)>& fn) {
  check_dims(desc);
  check_range(desc, lo, hi);
  const int64_t slice = desc.dims.x * desc.dims.y, nz = desc.dims.z;
  const int64_t slab_slices = std::clamp<int64_t>(max_slab_voxels / slice, 1, nz);
  const size_t esize = dtype_size(desc.dtype);
  const bool swap = needs_swap(desc);
  std::vector<float> slab;
  try {
    slab.resize(size_t(slab_slices * slice));
  } catch (const std::bad_alloc&) {
    fail("cannot allocate {:.1f} MiB for a slab of '{}'", double(slab_slices * slice) * 4 / (1 << 20), desc.path);
  }
  std::vector<unsigned char> buf(size_t(std::min<int64_t>(slab_slices * slice, kChunkVoxels) * int64_t(esize)));

  double pivot = 0;
  bool pivot_known = pivot_from_desc(desc, &pivot);
  PivotNormaliser norm(pivot, lo, hi, opts.non_finite);
  const bool strict = opts.non_finite == NonFinitePolicy::Error;
  Tally acc;
  SampleStream in(desc);
  for (int64_t z0 = 0; z0 < nz; z0 += slab_slices) {
    const int64_t k = std::min(slab_slices, nz - z0), count = k * slice;
    for (int64_t i = 0; i < count; i += kChunkVoxels) {
      const int64_t m = std::min(kChunkVoxels, count - i);
      in.read(buf.data(), uint64_t(m) * esize);
      with_sample_type(desc.dtype, [&](auto tag) {
        using T = typename decltype(tag)::type;
        if (!pivot_known && find_pivot<T>(buf.data(), m, swap, &pivot)) {
          pivot_known = true;
          norm.set(pivot, lo, hi, opts.non_finite);
        }
        acc.merge(convert<T>(buf.data(), m, uint64_t(z0 * slice + i), swap, pivot, slab.data() + i));
      });
      map_in_place(norm, slab.data() + i, m);
    }
    if (!(strict && acc.nonfinite > 0)) fn(z0, k, slab.data());
  }
  in.finish();
  if (strict && acc.nonfinite > 0) nonfinite_error(desc, acc.nonfinite, acc.first_nonfinite);
}

}  // namespace vnr
