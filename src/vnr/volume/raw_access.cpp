#include "vnr/volume/raw_access.h"
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <numeric>
#include <type_traits>
#include <vector>
#include "vnr/error.h"
#include "vnr/volume/dataset.h"
#include "vnr/volume/formats.h"

namespace vnr {

void require_random_access(const VolumeDesc& desc, const std::string& what, const std::string& alternative) {
  if (!detail::is_dataset_encoding(desc.encoding)) require_raw_bytes(desc, what, alternative);
}

void require_raw_bytes(const VolumeDesc& desc, const std::string& what, const std::string& alternative) {
  if (detail::is_dataset_encoding(desc.encoding))
    fail("'{}:{}' is an {} dataset, and {} needs the voxels as plain bytes in a file (raw, or NRRD with "
         "'encoding: raw'){}{}",
         desc.path, desc.dataset, desc.encoding == "hdf5" ? "HDF5" : "NetCDF", what,
         alternative.empty() ? "" : "; ", alternative);
  if (desc.encoding != "raw")
    fail("'{}' is {}-encoded, and {} reads voxels at random offsets, which needs uncompressed data (raw, or NRRD "
         "with 'encoding: raw'){}{}",
         desc.path, desc.encoding, what, alternative.empty() ? "" : "; ", alternative);
}

using namespace detail;

namespace {

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

// load_volume's pivot for desc's timestep: an explicit range end, else the first finite sample in
// file order; read(dst, first, n) reads voxels [first, first + n) of the timestep.
template <typename Read>
double pivot_of(const VolumeDesc& desc, bool swap, Read&& read) {
  double pivot = 0;
  if (pivot_from_desc(desc, &pivot)) return pivot;
  const int64_t n = int64_t(desc.dims.count()), esize = int64_t(dtype_size(desc.dtype));
  const int64_t per = std::min<int64_t>(n, int64_t(1) << 16);
  std::vector<unsigned char> buf(size_t(per * esize));
  bool found = false;
  for (int64_t i0 = 0; i0 < n && !found; i0 += per) {
    const int64_t m = std::min(per, n - i0);
    read(buf.data(), i0, m);
    with_sample_type(desc.dtype, [&](auto tag) {
      found = find_pivot<typename decltype(tag)::type>(buf.data(), m, swap, &pivot);
    });
  }
  return pivot;  // none found: every sample is NaN/Inf, and those do not use the pivot
}

double pivot_of(int fd, const VolumeDesc& desc) {
  const int64_t esize = int64_t(dtype_size(desc.dtype));
  return pivot_of(desc, needs_swap(desc), [&](unsigned char* dst, int64_t i0, int64_t m) {
    pread_exact(fd, dst, size_t(m * esize), desc.offset + uint64_t(i0 * esize), desc.path);
  });
}

// The data file of desc, open for reading, after the checks both access paths share: raw
// encoding, valid dims and range, a file that holds the timestep.
struct DataFile {
  int fd;
  FileIdentity id;
  double pivot;
};

DataFile open_data(const VolumeDesc& desc, double lo, double hi, const std::string& what,
                   const std::string& alternative) {
  require_raw_bytes(desc, what, alternative);
  check_dims(desc);
  check_range(desc, lo, hi);
  DataFile f;
  f.fd = ::open(desc.path.c_str(), O_RDONLY | O_CLOEXEC);
  if (f.fd < 0) fail("cannot open '{}': {}", desc.path, std::strerror(errno));
  try {
    f.id = identity_of_fd(f.fd, desc.path);
    const uint64_t need = desc.offset + desc.dims.count() * dtype_size(desc.dtype);
    if (f.id.size < need)
      fail("'{}' is {} bytes, expected at least {} ({} {} from byte {}; did the file change since it was described?)",
           desc.path, f.id.size, need, dims_string(desc.dims), dtype_name(desc.dtype), desc.offset);
    f.pivot = pivot_of(f.fd, desc);
  } catch (...) {
    ::close(f.fd);
    throw;
  }
  return f;
}

[[noreturn]] void nonfinite_voxel_error(const VolumeDesc& desc, int64_t x, int64_t y, int64_t z) {
  fail("'{}' contains NaN/Inf values (voxel ({},{},{}) is one); use --nan zero|clamp", desc.path, x, y, z);
}

// The normalised value of the stored sample at p (a T); NaN/Inf under NonFinitePolicy::Error is an
// error naming the voxel at `index` (x + nx * (y + ny * z)).
template <typename T>
float normalised_sample(const unsigned char* p, bool swap, bool strict, const PivotNormaliser& norm,
                        const VolumeDesc& desc, int64_t index) {
  const double v = element<T>(p, swap);
  if (std::is_floating_point_v<T> && strict && !std::isfinite(v)) {
    const int64_t nx = desc.dims.x, ny = desc.dims.y;
    nonfinite_voxel_error(desc, index % nx, (index / nx) % ny, index / (nx * ny));
  }
  return norm(v);
}

}  // namespace

// ---------------------------------------------------------------------------------------------
RawVolumeFile::RawVolumeFile(const VolumeDesc& desc, double lo, double hi, NonFinitePolicy policy,
                             const std::string& what, const std::string& alternative)
    : desc_(desc), policy_(policy) {
  if (is_dataset_encoding(desc.encoding)) {
    open_dataset(lo, hi);  // a dataset is read as hyperslabs: any reader may have it
    return;
  }
  DataFile f = open_data(desc, lo, hi, what, alternative);
  fd_ = f.fd;
  file_bytes_ = f.id.size;
  dev_ = f.id.dev;
  ino_ = f.id.ino;
  norm_.set(f.pivot, lo, hi, policy);
  esize_ = dtype_size(desc.dtype);
  swap_ = needs_swap(desc);
  frame_bytes_ = desc.dims.count() * esize_;
  // Voxels are read in random order: no readahead of data nobody asked for.
  ::posix_fadvise(fd_, 0, 0, POSIX_FADV_RANDOM);
}

RawVolumeFile::~RawVolumeFile() {
  if (fd_ >= 0) ::close(fd_);
}

// An HDF5/NetCDF source: the same checks and pivot as a raw file's, the container file's identity
// for check_unchanged, and reads through the library.
void RawVolumeFile::open_dataset(double lo, double hi) {
  check_dims(desc_);
  check_range(desc_, lo, hi);
  esize_ = dtype_size(desc_.dtype);
  swap_ = false;
  frame_bytes_ = desc_.dims.count() * esize_;
  struct stat st;
  if (::stat(desc_.path.c_str(), &st) != 0) fail("cannot stat '{}': {}", desc_.path, std::strerror(errno));
  file_bytes_ = uint64_t(st.st_size);
  dev_ = st.st_dev;
  ino_ = st.st_ino;
  dataset_ = open_dataset_reader(desc_);
  const double pivot = pivot_of(desc_, false, [&](unsigned char* dst, int64_t i0, int64_t m) {
    read_voxel_run(*dataset_, desc_.dims, uint64_t(i0), uint64_t(m), esize_, dst);
  });
  norm_.set(pivot, lo, hi, policy_);
}

void RawVolumeFile::read_bytes(unsigned char* dst, size_t bytes, uint64_t file_offset) const {
  if (dataset_) {
    read_voxel_run(*dataset_, desc_.dims, (file_offset - desc_.offset) / esize_, bytes / esize_, esize_, dst);
  } else {
    pread_exact(fd_, dst, bytes, file_offset, desc_.path);
  }
  count_read(bytes, file_offset);
}

void RawVolumeFile::count_read(size_t bytes, uint64_t file_offset) const {
  bytes_read_.fetch_add(bytes, std::memory_order_relaxed);
  uint64_t end = file_offset + bytes, cur = max_read_end_.load(std::memory_order_relaxed);
  while (end > cur && !max_read_end_.compare_exchange_weak(cur, end, std::memory_order_relaxed)) {
  }
  cur = min_read_begin_.load(std::memory_order_relaxed);
  while (file_offset < cur && !min_read_begin_.compare_exchange_weak(cur, file_offset, std::memory_order_relaxed)) {
  }
}

int64_t RawVolumeFile::rows_per_read(int64_t box_ny) const {
  // One pread covers several rows of a z-slice when the bytes between them are few: a disk pays per
  // request far more than per byte. At most ~1 MiB per read.
  const int64_t row_bytes = int64_t(desc_.dims.x) * int64_t(esize_);
  if (row_bytes > (16 << 10) || box_ny <= 1) return 1;
  return std::clamp<int64_t>((int64_t(1) << 20) / row_bytes, 1, std::min<int64_t>(box_ny, desc_.dims.y));
}

size_t RawVolumeFile::scratch_bytes(Int3 box) const {
  const int64_t in_row = std::min<int64_t>(box.x, desc_.dims.x);
  return size_t((rows_per_read(box.y) - 1) * int64_t(desc_.dims.x) + in_row) * esize_;
}

// A dataset's box: the part inside clamp_to as one hyperslab, then clamp-to-edge outside it.
void RawVolumeFile::read_dataset_box(Int3 origin, Int3 size, float* out, const Box3& c) const {
  const Int3 d = desc_.dims;
  Int3 lo, in;
  for (int a = 0; a < 3; ++a) {
    lo[a] = std::clamp<int64_t>(origin[a], c.lo[a], c.hi[a] - 1);
    in[a] = std::clamp<int64_t>(origin[a] + size[a], lo[a] + 1, c.hi[a]) - lo[a];  // >= 1: a box outside reads the edge
  }
  std::vector<unsigned char> buf(size_t(in.count() * esize_));
  dataset_->read_box(lo, in, buf.data());
  count_read(buf.size(), desc_.offset + uint64_t((lo.z * d.y + lo.y) * d.x + lo.x) * esize_);
  const bool strict = policy_ == NonFinitePolicy::Error;
  const PivotNormaliser norm = norm_;
  auto inside = [](int64_t v, int64_t lo_, int64_t n) { return std::clamp<int64_t>(v, lo_, lo_ + n - 1) - lo_; };
  with_sample_type(desc_.dtype, [&](auto tag) {
    using T = typename decltype(tag)::type;
    for (int64_t k = 0; k < size.z; ++k) {
      const int64_t bz = inside(origin.z + k, lo.z, in.z);
      for (int64_t j = 0; j < size.y; ++j) {
        const int64_t by = inside(origin.y + j, lo.y, in.y);
        float* row = out + (k * size.y + j) * size.x;
        for (int64_t i = 0; i < size.x; ++i) {
          const int64_t bx = inside(origin.x + i, lo.x, in.x);
          const int64_t voxel = ((lo.z + bz) * d.y + lo.y + by) * d.x + lo.x + bx;
          row[i] = normalised_sample<T>(buf.data() + ((bz * in.y + by) * in.x + bx) * int64_t(esize_), false, strict,
                                        norm, desc_, voxel);
        }
      }
    }
  });
}

void RawVolumeFile::read_box(Int3 origin, Int3 size, float* out, unsigned char* scratch) const {
  read_box(origin, size, out, scratch, Box3{{0, 0, 0}, desc_.dims});
}

void RawVolumeFile::read_box(Int3 origin, Int3 size, float* out, unsigned char* scratch, const Box3& c) const {
  const Int3 d = desc_.dims;
  for (int a = 0; a < 3; ++a)
    if (c.lo[a] < 0 || c.hi[a] > d[a] || c.hi[a] <= c.lo[a])
      fail("read_box: clamp box [{}, {}) x [{}, {}) x [{}, {}) is empty or outside the {}x{}x{} volume", c.lo.x,
           c.hi.x, c.lo.y, c.hi.y, c.lo.z, c.hi.z, d.x, d.y, d.z);
  if (dataset_) return read_dataset_box(origin, size, out, c);
  auto clamp = [](int64_t v, int64_t lo, int64_t hi) { return v < lo ? lo : (v >= hi ? hi - 1 : v); };
  // The part of each row inside the clamp box; columns outside copy its edge voxel.
  const int64_t x_lo = std::max<int64_t>(origin.x, c.lo.x), x_hi = std::min<int64_t>(origin.x + size.x, c.hi.x);
  const int64_t in_row = x_hi - x_lo;
  if (in_row <= 0) fail("read_box: box x range [{}, {}) misses [{}, {})", origin.x, origin.x + size.x, c.lo.x, c.hi.x);
  const int64_t lead = x_lo - origin.x;
  const bool strict = policy_ == NonFinitePolicy::Error;
  const int64_t max_rows = rows_per_read(size.y), file_row = int64_t(d.x) * int64_t(esize_);
  const int64_t slice_floats = size.x * size.y;
  const PivotNormaliser norm = norm_;  // a local copy: the float stores below cannot touch it
  with_sample_type(desc_.dtype, [&](auto tag) {
    using T = typename decltype(tag)::type;
    for (int64_t k = 0; k < size.z; ++k) {
      const int64_t z = clamp(origin.z + k, c.lo.z, c.hi.z);
      float* slice = out + k * slice_floats;
      // Slices repeated by the clamp (ghost layers on the border) are copied, not read again.
      if (k > 0 && z == clamp(origin.z + k - 1, c.lo.z, c.hi.z)) {
        std::memcpy(slice, slice - slice_floats, sizeof(float) * size_t(slice_floats));
        continue;
      }
      for (int64_t j = 0; j < size.y;) {
        const int64_t y = clamp(origin.y + j, c.lo.y, c.hi.y);
        if (j > 0 && y == clamp(origin.y + j - 1, c.lo.y, c.hi.y)) {  // a repeated row: copy it
          std::memcpy(slice + j * size.x, slice + (j - 1) * size.x, sizeof(float) * size_t(size.x));
          ++j;
          continue;
        }
        // A run of consecutive file rows y, y+1, ... read with one pread.
        int64_t rows = 1;
        while (rows < max_rows && j + rows < size.y && clamp(origin.y + j + rows, c.lo.y, c.hi.y) == y + rows) ++rows;
        const int64_t first = (z * d.y + y) * d.x + x_lo;  // voxel index of the run's first sample
        read_bytes(scratch, size_t((rows - 1) * file_row) + size_t(in_row) * esize_,
                   desc_.offset + uint64_t(first) * esize_);
        for (int64_t r = 0; r < rows; ++r) {
          float* row = slice + (j + r) * size.x;
          const unsigned char* src = scratch + r * file_row;
          for (int64_t i = 0; i < in_row; ++i)
            row[lead + i] = normalised_sample<T>(src + i * int64_t(sizeof(T)), swap_, strict, norm, desc_,
                                                 first + r * d.x + i);
          for (int64_t i = 0; i < lead; ++i) row[i] = row[lead];
          for (int64_t i = lead + in_row; i < size.x; ++i) row[i] = row[lead + in_row - 1];
        }
        j += rows;
      }
    }
  });
}

void RawVolumeFile::read_voxels(const int64_t* voxel_index, int64_t n, float* out) const {
  if (n <= 0) return;
  const int64_t n_voxels = voxel_count(), esize = int64_t(esize_);
  for (int64_t i = 0; i < n; ++i)
    if (voxel_index[i] < 0 || voxel_index[i] >= n_voxels)
      fail("'{}': voxel index {} out of range (the volume has {} voxels)", desc_.path, voxel_index[i], n_voxels);

  // Visit the voxels in file order and read nearby ones with one pread: a run grows while the next
  // voxel is within kMaxGap bytes and the run stays under kMaxRun bytes.
  constexpr int64_t kMaxGap = 16 << 10, kMaxRun = 1 << 20;
  std::vector<int64_t> order(static_cast<size_t>(n));
  std::iota(order.begin(), order.end(), int64_t(0));
  std::sort(order.begin(), order.end(), [&](int64_t a, int64_t b) { return voxel_index[a] < voxel_index[b]; });
  std::vector<unsigned char> buf(size_t(kMaxRun + esize));
  for (int64_t s = 0; s < n;) {
    const int64_t first = voxel_index[order[size_t(s)]];
    int64_t e = s + 1;
    while (e < n) {
      const int64_t v = voxel_index[order[size_t(e)]], prev = voxel_index[order[size_t(e - 1)]];
      if ((v - prev) * esize > kMaxGap || (v - first + 1) * esize > kMaxRun) break;
      ++e;
    }
    const int64_t last = voxel_index[order[size_t(e - 1)]];
    read_bytes(buf.data(), size_t((last - first + 1) * esize), desc_.offset + uint64_t(first * esize));
    with_sample_type(desc_.dtype, [&](auto tag) {
      using T = typename decltype(tag)::type;
      for (int64_t k = s; k < e; ++k) {
        const int64_t idx = voxel_index[order[size_t(k)]];
        out[order[size_t(k)]] = normalised_sample<T>(buf.data() + (idx - first) * esize, swap_,
                                                     policy_ == NonFinitePolicy::Error, norm_, desc_, idx);
      }
    });
    s = e;
  }
}

void RawVolumeFile::check_unchanged() const { check_same_file(desc_.path, file_bytes_, dev_, ino_); }

// ---------------------------------------------------------------------------------------------
MappedVolume::MappedVolume(const VolumeDesc& desc, double lo, double hi, NonFinitePolicy policy) : desc_(desc) {
  // Non-finite values cannot be reported from inside a lookup: they read as lo (or hi for +Inf
  // under --nan clamp); the value-range pass has already refused them unless --nan allowed them.
  DataFile f = open_data(desc, lo, hi, "memory-mapped sampling", "");
  file_bytes_ = f.id.size;
  dev_ = f.id.dev;
  ino_ = f.id.ino;
  norm_.set(f.pivot, lo, hi, policy);
  swap_ = needs_swap(desc);
  const uint64_t frame = desc.dims.count() * dtype_size(desc.dtype);
  const uint64_t page = uint64_t(::sysconf(_SC_PAGESIZE));
  const uint64_t start = desc.offset / page * page;
  map_bytes_ = size_t(desc.offset + frame - start);
  map_ = ::mmap(nullptr, map_bytes_, PROT_READ, MAP_SHARED, f.fd, off_t(start));
  ::close(f.fd);
  if (map_ == MAP_FAILED) fail("cannot memory-map '{}': {}", desc.path, std::strerror(errno));
  ::madvise(map_, map_bytes_, MADV_RANDOM);
  base_ = static_cast<const unsigned char*>(map_) + (desc.offset - start);
}

MappedVolume::~MappedVolume() {
  if (map_ && map_ != MAP_FAILED) ::munmap(map_, map_bytes_);
}

void MappedVolume::lookup(const float* x, const float* y, const float* z, int64_t n, float* out) const {
  const Int3 d = desc_.dims;
  with_sample_type(desc_.dtype, [&](auto tag) {
    using T = typename decltype(tag)::type;
    const T* data = reinterpret_cast<const T*>(base_);
    const int64_t sy = d.x, sz = d.x * d.y;
    const bool swap = swap_;
    const PivotNormaliser norm = norm_;
    auto at = [&](int32_t i, int32_t j, int32_t k) {
      return norm(element<T>(reinterpret_cast<const unsigned char*>(data + (i + j * sy + k * sz)), swap));
    };
    for (int64_t s = 0; s < n; ++s)
      out[s] = cell_centred_trilinear(int32_t(d.x), int32_t(d.y), int32_t(d.z), x[s], y[s], z[s], at);
  });
}

void MappedVolume::check_unchanged() const { check_same_file(desc_.path, file_bytes_, dev_, ino_); }

}  // namespace vnr
