#include "vnr/volume/raw_access.h"
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>
#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <vector>
#include "vnr/core/error.h"

namespace vnr {
namespace {

template <typename T>
inline double load_element(const unsigned char* p, bool swap) {
  unsigned char b[sizeof(T)];
  if (swap) {
    for (size_t i = 0; i < sizeof(T); ++i) b[i] = p[sizeof(T) - 1 - i];
  } else {
    std::memcpy(b, p, sizeof(T));
  }
  T v;
  std::memcpy(&v, b, sizeof(T));
  return double(v);
}

template <typename F>
decltype(auto) with_element_type(DType t, F&& f) {
  switch (t) {
    case DType::Int8: return f(int8_t{});
    case DType::UInt8: return f(uint8_t{});
    case DType::Int16: return f(int16_t{});
    case DType::UInt16: return f(uint16_t{});
    case DType::Int32: return f(int32_t{});
    case DType::UInt32: return f(uint32_t{});
    case DType::Float32: return f(float{});
    case DType::Float64: return f(double{});
  }
  return f(float{});
}

struct FileIdentity {
  uint64_t size;
  dev_t dev;
  ino_t ino;
};

FileIdentity identity_of_fd(int fd, const std::string& path) {
  struct stat st;
  if (::fstat(fd, &st) != 0) fail("cannot stat '{}': {}", path, std::strerror(errno));
  return {uint64_t(st.st_size), st.st_dev, st.st_ino};
}

// The checks shared by both access paths: the file is still there, is the same file, and has
// the size it had when training started.
void check_same_file(const std::string& path, uint64_t size, dev_t dev, ino_t ino) {
  struct stat st;
  if (::stat(path.c_str(), &st) != 0) {
    if (errno == ENOENT) fail("the volume file '{}' disappeared during training", path);
    fail("cannot stat the volume file '{}': {}", path, std::strerror(errno));
  }
  if (st.st_dev != dev || st.st_ino != ino)
    fail("the volume file '{}' was replaced by another file during training", path);
  if (uint64_t(st.st_size) != size)
    fail("the volume file '{}' changed size during training: {} bytes, now {}", path, size, uint64_t(st.st_size));
}

void require_raw(const VolumeDesc& desc, const char* what) {
  if (desc.encoding != "raw")
    fail("'{}' is {}-compressed; {} needs uncompressed data (write a raw copy with `vnr convert`)", desc.path,
         desc.encoding, what);
}

}  // namespace

int64_t normalise_elements(DType dtype, bool swap, const unsigned char* src, int64_t n, const Normaliser& norm,
                           float* out) {
  return with_element_type(dtype, [&](auto tag) -> int64_t {
    using T = decltype(tag);
    int64_t first_bad = -1;
    for (int64_t i = 0; i < n; ++i) {
      double v = load_element<T>(src + size_t(i) * sizeof(T), swap);
      if constexpr (std::is_floating_point_v<T>)
        if (first_bad < 0 && !std::isfinite(v)) first_bad = i;
      out[i] = norm(v);
    }
    return first_bad;
  });
}

// ---------------------------------------------------------------------------------------------
RawVolumeFile::RawVolumeFile(const VolumeDesc& desc, double lo, double hi, NonFinitePolicy policy)
    : desc_(desc), norm_(lo, hi, policy), policy_(policy) {
  require_raw(desc, "out-of-core sampling");
  esize_ = dtype_size(desc.dtype);
  swap_ = desc.big_endian != (std::endian::native == std::endian::big);
  frame_bytes_ = desc.dims.count() * esize_;
  fd_ = ::open(desc.path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) fail("cannot open '{}': {}", desc.path, std::strerror(errno));
  FileIdentity id = identity_of_fd(fd_, desc.path);
  file_bytes_ = id.size;
  dev_ = id.dev;
  ino_ = id.ino;
  if (desc.offset + frame_bytes_ > file_bytes_) {
    ::close(fd_);
    fail("'{}' holds {} bytes, but timestep {} needs bytes {}..{}", desc.path, file_bytes_, desc.timestep, desc.offset,
         desc.offset + frame_bytes_);
  }
  // Blocks are read in random order: no readahead of data nobody asked for.
  ::posix_fadvise(fd_, 0, 0, POSIX_FADV_RANDOM);
}

RawVolumeFile::~RawVolumeFile() {
  if (fd_ >= 0) ::close(fd_);
}

void RawVolumeFile::pread_exact(unsigned char* dst, size_t bytes, uint64_t file_offset) const {
  size_t done = 0;
  while (done < bytes) {
    ssize_t r = ::pread(fd_, dst + done, bytes - done, off_t(file_offset + done));
    if (r < 0) {
      if (errno == EINTR) continue;
      fail("cannot read '{}' at byte {}: {}", desc_.path, file_offset + done, std::strerror(errno));
    }
    if (r == 0)
      fail("the volume file '{}' ended at byte {} while reading voxels up to byte {}: it changed size during training",
           desc_.path, file_offset + done, file_offset + bytes);
    done += size_t(r);
  }
  bytes_read_.fetch_add(bytes, std::memory_order_relaxed);
  uint64_t end = file_offset + bytes, cur = max_read_end_.load(std::memory_order_relaxed);
  while (end > cur && !max_read_end_.compare_exchange_weak(cur, end, std::memory_order_relaxed)) {
  }
  cur = min_read_begin_.load(std::memory_order_relaxed);
  while (file_offset < cur && !min_read_begin_.compare_exchange_weak(cur, file_offset, std::memory_order_relaxed)) {
  }
}

void RawVolumeFile::read_box(Int3 origin, Int3 size, float* out, unsigned char* scratch) const {
  const Int3 d = desc_.dims;
  auto clamp = [](int64_t v, int64_t n) { return v < 0 ? 0 : (v >= n ? n - 1 : v); };
  // The part of each row inside the volume; columns outside copy the edge voxel.
  const int64_t x_lo = std::max<int64_t>(origin.x, 0), x_hi = std::min<int64_t>(origin.x + size.x, d.x);
  const int64_t in_row = x_hi - x_lo;
  if (in_row <= 0) fail("read_box: box x range [{}, {}) misses the volume", origin.x, origin.x + size.x);
  const int64_t lead = x_lo - origin.x;
  for (int64_t k = 0; k < size.z; ++k) {
    const int64_t z = clamp(origin.z + k, d.z);
    for (int64_t j = 0; j < size.y; ++j) {
      const int64_t y = clamp(origin.y + j, d.y);
      float* row = out + (k * size.y + j) * size.x;
      // Rows repeated by the clamp (ghost layers on the border) are copied, not read again.
      if (j > 0 && y == clamp(origin.y + j - 1, d.y)) {
        std::memcpy(row, row - size.x, sizeof(float) * size_t(size.x));
        continue;
      }
      if (k > 0 && z == clamp(origin.z + k - 1, d.z)) {
        std::memcpy(row, row - size.x * size.y, sizeof(float) * size_t(size.x));
        continue;
      }
      const uint64_t voxel = (uint64_t(z) * uint64_t(d.y) + uint64_t(y)) * uint64_t(d.x) + uint64_t(x_lo);
      pread_exact(scratch, size_t(in_row) * esize_, desc_.offset + voxel * esize_);
      int64_t bad = normalise_elements(desc_.dtype, swap_, scratch, in_row, norm_, row + lead);
      if (bad >= 0 && policy_ == NonFinitePolicy::Error)
        fail("'{}' contains NaN/Inf (voxel ({},{},{})); use --nan zero|clamp", desc_.path, x_lo + bad, y, z);
      for (int64_t i = 0; i < lead; ++i) row[i] = row[lead];
      for (int64_t i = lead + in_row; i < size.x; ++i) row[i] = row[lead + in_row - 1];
    }
  }
}

void RawVolumeFile::check_unchanged() const { check_same_file(desc_.path, file_bytes_, dev_, ino_); }

// ---------------------------------------------------------------------------------------------
MappedVolume::MappedVolume(const VolumeDesc& desc, double lo, double hi, NonFinitePolicy policy)
    : desc_(desc), norm_(lo, hi, policy) {
  require_raw(desc, "memory-mapped sampling");
  // Non-finite values cannot be reported from inside a lookup: they read as lo (or hi for +Inf
  // under --nan clamp); the value-range pass has already refused them unless --nan allowed them.
  swap_ = desc.big_endian != (std::endian::native == std::endian::big);
  const uint64_t frame = desc.dims.count() * dtype_size(desc.dtype);
  int fd = ::open(desc.path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) fail("cannot open '{}': {}", desc.path, std::strerror(errno));
  FileIdentity id = identity_of_fd(fd, desc.path);
  file_bytes_ = id.size;
  dev_ = id.dev;
  ino_ = id.ino;
  if (desc.offset + frame > file_bytes_) {
    ::close(fd);
    fail("'{}' holds {} bytes, but timestep {} needs bytes {}..{}", desc.path, file_bytes_, desc.timestep, desc.offset,
         desc.offset + frame);
  }
  const uint64_t page = uint64_t(::sysconf(_SC_PAGESIZE));
  const uint64_t start = desc.offset / page * page;
  map_bytes_ = size_t(desc.offset + frame - start);
  map_ = ::mmap(nullptr, map_bytes_, PROT_READ, MAP_SHARED, fd, off_t(start));
  ::close(fd);
  if (map_ == MAP_FAILED) fail("cannot memory-map '{}': {}", desc.path, std::strerror(errno));
  ::madvise(map_, map_bytes_, MADV_RANDOM);
  base_ = static_cast<const unsigned char*>(map_) + (desc.offset - start);
}

MappedVolume::~MappedVolume() {
  if (map_ && map_ != MAP_FAILED) ::munmap(map_, map_bytes_);
}

void MappedVolume::lookup(const float* x, const float* y, const float* z, int64_t n, float* out) const {
  const Int3 d = desc_.dims;
  with_element_type(desc_.dtype, [&](auto tag) {
    using T = decltype(tag);
    const T* data = reinterpret_cast<const T*>(base_);
    const int64_t sy = d.x, sz = d.x * d.y;
    const bool swap = swap_;
    const Normaliser norm = norm_;
    auto at = [&](int32_t i, int32_t j, int32_t k) {
      return norm(load_element<T>(reinterpret_cast<const unsigned char*>(data + (i + j * sy + k * sz)), swap));
    };
    for (int64_t s = 0; s < n; ++s)
      out[s] = cell_centred_trilinear(int32_t(d.x), int32_t(d.y), int32_t(d.z), x[s], y[s], z[s], at);
  });
}

void MappedVolume::check_unchanged() const { check_same_file(desc_.path, file_bytes_, dev_, ino_); }

}  // namespace vnr
