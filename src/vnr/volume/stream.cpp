// Streaming and random-access readers for volumes larger than memory. The conversion and
// normalisation steps repeat load_volume's (load.cpp) operation for operation — the same pivot,
// the same float rounding of v - pivot, the same double arithmetic afterwards — so that the values
// are bit-identical to an in-memory load; tests/test_stream_eval.cpp checks this on every dtype.
#include "vnr/volume/stream.h"
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>
#include <algorithm>
#include <bit>
#include <cerrno>
#include <cfloat>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <new>
#include <numeric>
#include <type_traits>
#include "vnr/core/error.h"
#include "vnr/core/parallel.h"
#include "vnr/volume/formats.h"

namespace vnr {
namespace {

// Voxels converted per read: at most 8 MiB of float64 input, whatever the volume size.
constexpr int64_t kChunkVoxels = int64_t(1) << 20;
constexpr int64_t kGrain = int64_t(1) << 16;

template <typename T>
struct TypeTag {
  using type = T;
};

// Calls f(TypeTag<T>{}) with the C++ type of a sample of dtype t.
template <typename F>
void with_sample_type(DType t, F&& f) {
  switch (t) {
    case DType::Int8: return f(TypeTag<int8_t>{});
    case DType::UInt8: return f(TypeTag<uint8_t>{});
    case DType::Int16: return f(TypeTag<int16_t>{});
    case DType::UInt16: return f(TypeTag<uint16_t>{});
    case DType::Int32: return f(TypeTag<int32_t>{});
    case DType::UInt32: return f(TypeTag<uint32_t>{});
    case DType::Float32: return f(TypeTag<float>{});
    case DType::Float64: return f(TypeTag<double>{});
  }
}

template <typename T>
inline double element(const unsigned char* p, bool swap) {
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

bool needs_swap(const VolumeDesc& d) { return d.big_endian != (std::endian::native == std::endian::big); }

void check_dims(const VolumeDesc& desc) {
  const Int3 d = desc.dims;
  if (d.x <= 0 || d.y <= 0 || d.z <= 0 || d.x > (1 << 30) || d.y > (1 << 30) || d.z > (1 << 30) ||
      d.count() > (uint64_t(1) << 40))
    fail("'{}': invalid dims {}", desc.path, detail::dims_string(d));
}

void check_range(const VolumeDesc& desc, double lo, double hi) {
  if (!std::isfinite(lo) || !std::isfinite(hi)) fail("'{}': value range must be finite", desc.path);
  if (lo > hi) fail("'{}': invalid value range [{}, {}] (lo > hi)", desc.path, lo, hi);
}

// load_volume's pivot when the description fixes it (an explicit range end); otherwise the first
// finite value of the data, found while reading.
bool pivot_from_desc(const VolumeDesc& desc, double* pivot) {
  *pivot = desc.range_lo ? *desc.range_lo : desc.range_hi.value_or(0.0);
  return desc.range_lo || desc.range_hi;
}

[[noreturn]] void nonfinite_error(const VolumeDesc& desc, uint64_t count, uint64_t first) {
  const Int3 d = desc.dims;
  uint64_t xy = uint64_t(d.x) * uint64_t(d.y);
  fail("'{}' contains {} NaN/Inf values (first at voxel ({},{},{})); use --nan zero|clamp", desc.path, count,
       first % uint64_t(d.x), (first / uint64_t(d.x)) % uint64_t(d.y), first / xy);
}

// load_volume's normalisation of one finite or non-finite sample, given its pivot: the sample is
// first stored as float(v - pivot) (load.cpp keeps that float copy), then mapped in double.
struct PivotNormaliser {
  double pivot = 0, shift = 0, inv = 0;
  bool clamp_inf = false;
  void set(double pivot_, double lo, double hi, NonFinitePolicy policy) {
    pivot = pivot_;
    shift = lo - pivot;
    inv = hi > lo ? 1.0 / (hi - lo) : 0.0;  // constant volume -> all 0
    clamp_inf = policy == NonFinitePolicy::Clamp;
  }
  float operator()(double v) const {
    if (!std::isfinite(v)) return (clamp_inf && v > 0 && inv > 0) ? 1.f : 0.f;  // NaN, -Inf -> lo; +Inf -> hi|lo
    float s = float(std::clamp(v - pivot, -double(FLT_MAX), double(FLT_MAX)));
    double u = (double(s) - shift) * inv;
    return u <= 0 ? 0.f : (u >= 1 ? 1.f : float(u));
  }
};

// Finite min/max and non-finite count of a stretch of data; merged in any order gives one result.
struct Tally {
  double lo = std::numeric_limits<double>::infinity();
  double hi = -std::numeric_limits<double>::infinity();
  uint64_t nonfinite = 0;
  uint64_t first_nonfinite = std::numeric_limits<uint64_t>::max();
  void merge(const Tally& o) {
    lo = std::min(lo, o.lo);
    hi = std::max(hi, o.hi);
    nonfinite += o.nonfinite;
    first_nonfinite = std::min(first_nonfinite, o.first_nonfinite);
  }
};

// Tallies n samples starting at voxel `first`; when out != nullptr also normalises them into out
// (then norm.pivot must be final, see find_pivot).
template <typename T>
Tally convert(const unsigned char* buf, int64_t n, uint64_t first, bool swap, const PivotNormaliser* norm,
            float* out) {
  std::vector<Tally> parts(size_t(std::max<int64_t>(1, (n + kGrain - 1) / kGrain)));
  parallel_for_range(n, kGrain, [&](int64_t b, int64_t e) {
    Tally t;
    for (int64_t i = b; i < e; ++i) {
      double v = element<T>(buf + i * int64_t(sizeof(T)), swap);
      if (std::is_floating_point_v<T> && !std::isfinite(v)) {
        if (t.nonfinite++ == 0) t.first_nonfinite = first + uint64_t(i);
      } else {
        t.lo = std::min(t.lo, v);
        t.hi = std::max(t.hi, v);
      }
      if (out) out[i] = (*norm)(v);
    }
    parts[size_t(b / kGrain)] = t;
  });
  Tally all;
  for (const Tally& t : parts) all.merge(t);
  return all;
}

// The first finite sample of buf, if any: load_volume's pivot when the description sets none.
template <typename T>
bool find_pivot(const unsigned char* buf, int64_t n, bool swap, double* pivot) {
  for (int64_t i = 0; i < n; ++i) {
    double v = element<T>(buf + i * int64_t(sizeof(T)), swap);
    if (std::isfinite(v)) {
      *pivot = v;
      return true;
    }
  }
  return false;
}

// pread of exactly `bytes` at file offset `at` (a short read means the file shrank).
void pread_exact(int fd, unsigned char* dst, size_t bytes, uint64_t at, const std::string& path) {
  for (size_t done = 0; done < bytes;) {
    ssize_t r = ::pread(fd, dst + done, bytes - done, off_t(at + done));
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) fail("cannot read '{}': {}", path, std::strerror(errno));
    if (r == 0)
      fail("'{}': unexpected end of file at byte {} (did the file change since it was described?)", path, at + done);
    done += size_t(r);
  }
}

// The voxels of one timestep in file order, from a raw file or a gzip stream, with load_volume's
// messages for short or corrupt data.
class SampleStream {
public:
  explicit SampleStream(const VolumeDesc& desc) : desc_(desc) {
    frame_ = desc.dims.count() * dtype_size(desc.dtype);
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
  ~SampleStream() { close(); }
  SampleStream(const SampleStream&) = delete;
  SampleStream& operator=(const SampleStream&) = delete;

  void read(unsigned char* dst, uint64_t bytes) {
    if (gz_) {
      if (gz_read(dst, bytes) != bytes) gz_size_error();
      return;
    }
    size_t n = std::fread(dst, 1, size_t(bytes), f_);
    pos_ += n;
    if (n != bytes) {
      if (std::ferror(f_)) fail("cannot read '{}': {}", desc_.path, std::strerror(errno));
      fail("'{}': unexpected end of file at byte {} (did the file change since it was described?)", desc_.path,
           pos_);
    }
  }
  // After the last voxel: a gzip stream must hold exactly what the description says (as in
  // load_volume), which means decompressing any later timesteps too.
  void finish() {
    if (gz_ && gz_drain() != gz_expected()) gz_size_error();
  }

private:
  void close() {
    if (gz_) gzclose(gz_);
    if (f_) std::fclose(f_);
    gz_ = nullptr;
    f_ = nullptr;
  }
  uint64_t gz_read(unsigned char* dst, uint64_t bytes) {
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
  uint64_t gz_drain() {
    std::vector<unsigned char> tmp(1 << 18);
    while (gz_read(tmp.data(), tmp.size()) == tmp.size()) {
    }
    return gz_total_;
  }
  uint64_t gz_base() const { return desc_.offset - uint64_t(desc_.timestep) * frame_; }
  uint64_t gz_expected() const { return gz_base() + uint64_t(desc_.n_timesteps) * frame_; }
  [[noreturn]] void gz_size_error() {
    fail("'{}' decompresses to {} bytes, expected {} ({} {} + byte skip {})", desc_.path, gz_drain(), gz_expected(),
         detail::dims_string(desc_.dims, desc_.n_timesteps), dtype_name(desc_.dtype), gz_base());
  }

  const VolumeDesc& desc_;
  uint64_t frame_ = 0;
  std::FILE* f_ = nullptr;
  uint64_t pos_ = 0;
  gzFile gz_ = nullptr;
  uint64_t gz_total_ = 0;
};

}  // namespace

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
        acc.merge(convert<T>(buf.data(), int64_t(m), i0, swap, nullptr, nullptr));
      });
      if (progress) progress(double(i0 + m) / double(n));
    }
    in.finish();
    if (acc.nonfinite > 0 && opts.non_finite == NonFinitePolicy::Error)
      nonfinite_error(desc, acc.nonfinite, acc.first_nonfinite);
  }
  // load_volume's rule: explicit ends win, the data's finite min/max fill in the rest (B.1).
  const bool any_finite = acc.lo <= acc.hi;
  double lo = desc.range_lo ? *desc.range_lo : (any_finite ? acc.lo : (desc.range_hi ? *desc.range_hi : 0.0));
  double hi = desc.range_hi ? *desc.range_hi : (any_finite ? acc.hi : lo);
  if (!std::isfinite(lo) || !std::isfinite(hi)) fail("'{}': value range must be finite", desc.path);
  if (desc.range_lo && desc.range_hi && lo > hi)
    fail("'{}': invalid value range [{}, {}] (lo > hi)", desc.path, lo, hi);
  if (hi < lo) hi = lo;  // one explicit end beyond all data: everything maps to one end
  return ValueRange{lo, hi};
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

  PivotNormaliser norm;
  double pivot = 0;
  bool pivot_known = pivot_from_desc(desc, &pivot);
  norm.set(pivot, lo, hi, opts.non_finite);
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
        // Samples before the first finite one are all NaN/Inf and do not use the pivot.
        if (!pivot_known && find_pivot<T>(buf.data(), m, swap, &pivot)) {
          pivot_known = true;
          norm.set(pivot, lo, hi, opts.non_finite);
        }
        acc.merge(convert<T>(buf.data(), m, uint64_t(z0 * slice + i), swap, &norm, slab.data() + i));
      });
    }
    if (!(strict && acc.nonfinite > 0)) fn(z0, k, slab.data());
  }
  in.finish();
  if (strict && acc.nonfinite > 0) nonfinite_error(desc, acc.nonfinite, acc.first_nonfinite);
}

VoxelReader::VoxelReader(const VolumeDesc& desc, double lo, double hi, const LoadOptions& opts)
    : desc_(desc), opts_(opts) {
  if (desc.encoding == "gzip")
    fail("'{}' is gzip-encoded, and sampled evaluation reads single voxels, which needs uncompressed data; "
         "store the volume uncompressed (raw or NRRD 'encoding: raw') or evaluate it whole, which streams",
         desc.path);
  check_dims(desc);
  check_range(desc, lo, hi);
  n_voxels_ = int64_t(desc.dims.count());
  const uint64_t esize = dtype_size(desc.dtype);
  fd_ = ::open(desc.path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) fail("cannot open '{}': {}", desc.path, std::strerror(errno));
  try {
    struct stat st {};
    const uint64_t need = desc.offset + uint64_t(n_voxels_) * esize;
    if (::fstat(fd_, &st) != 0) fail("cannot stat '{}': {}", desc.path, std::strerror(errno));
    if (uint64_t(st.st_size) < need)
      fail("'{}' is {} bytes, expected at least {} ({} {} from byte {}; did the file change since it was described?)",
           desc.path, uint64_t(st.st_size), need, detail::dims_string(desc.dims), dtype_name(desc.dtype), desc.offset);
    // load_volume's pivot: an explicit range end, else the first finite sample in file order.
    double pivot = 0;
    if (!pivot_from_desc(desc, &pivot)) {
      const int64_t per = std::min<int64_t>(n_voxels_, int64_t(1) << 16);
      std::vector<unsigned char> buf(size_t(per) * esize);
      bool found = false;
      for (int64_t i0 = 0; i0 < n_voxels_ && !found; i0 += per) {
        const int64_t m = std::min(per, n_voxels_ - i0);
        pread_exact(fd_, buf.data(), size_t(m) * esize, desc.offset + uint64_t(i0) * esize, desc.path);
        with_sample_type(desc.dtype, [&](auto tag) {
          using T = typename decltype(tag)::type;
          found = find_pivot<T>(buf.data(), m, needs_swap(desc), &pivot);
        });
      }
    }
    PivotNormaliser norm;
    norm.set(pivot, lo, hi, opts.non_finite);
    pivot_ = norm.pivot;
    shift_ = norm.shift;
    inv_ = norm.inv;
  } catch (...) {
    ::close(fd_);
    fd_ = -1;
    throw;
  }
}

VoxelReader::~VoxelReader() {
  if (fd_ >= 0) ::close(fd_);
}

void VoxelReader::read(const int64_t* voxel_index, int64_t n, float* out) const {
  if (n <= 0) return;
  const int64_t esize = int64_t(dtype_size(desc_.dtype));
  const bool swap = needs_swap(desc_);
  PivotNormaliser norm;
  norm.pivot = pivot_;
  norm.shift = shift_;
  norm.inv = inv_;
  norm.clamp_inf = opts_.non_finite == NonFinitePolicy::Clamp;
  for (int64_t i = 0; i < n; ++i)
    if (voxel_index[i] < 0 || voxel_index[i] >= n_voxels_)
      fail("'{}': voxel index {} out of range (the volume has {} voxels)", desc_.path, voxel_index[i], n_voxels_);

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
    const size_t bytes = size_t((last - first + 1) * esize);
    pread_exact(fd_, buf.data(), bytes, desc_.offset + uint64_t(first * esize), desc_.path);
    with_sample_type(desc_.dtype, [&](auto tag) {
      using T = typename decltype(tag)::type;
      for (int64_t k = s; k < e; ++k) {
        const int64_t idx = voxel_index[order[size_t(k)]];
        double v = element<T>(buf.data() + (idx - first) * esize, swap);
        if (!std::isfinite(v) && opts_.non_finite == NonFinitePolicy::Error) {
          const uint64_t x = uint64_t(desc_.dims.x), xy = x * uint64_t(desc_.dims.y), u = uint64_t(idx);
          fail("'{}' contains NaN/Inf values (voxel ({},{},{}) is one); use --nan zero|clamp", desc_.path, u % x,
               (u / x) % uint64_t(desc_.dims.y), u / xy);
        }
        out[order[size_t(k)]] = norm(v);
      }
    });
    s = e;
  }
}

}  // namespace vnr
