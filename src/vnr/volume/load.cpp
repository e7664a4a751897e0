// load_volume: one streaming pass over the file (raw or gzip), conversion to float, then
// normalisation in place (compat.md B.1).
#include <fcntl.h>
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
#include "vnr/core/error.h"
#include "vnr/core/parallel.h"
#include "vnr/volume/formats.h"
#include "vnr/volume/volume.h"

namespace vnr {
namespace {

class RawReader {
public:
  RawReader(const std::string& path, uint64_t offset) : path_(path), pos_(offset) {
    f_ = std::fopen(path.c_str(), "rb");
    if (!f_) fail("cannot open '{}': {}", path, std::strerror(errno));
    if (fseeko(f_, off_t(offset), SEEK_SET) != 0) fail("cannot seek to byte {} in '{}'", offset, path);
  }
  ~RawReader() { std::fclose(f_); }
  void read_exact(unsigned char* dst, size_t bytes) {
    size_t n = std::fread(dst, 1, bytes, f_);
    pos_ += n;
    if (n != bytes) {
      if (std::ferror(f_)) fail("cannot read '{}': {}", path_, std::strerror(errno));
      fail("'{}': unexpected end of file at byte {} (did the file change since it was described?)", path_, pos_);
    }
  }

private:
  std::string path_;
  uint64_t pos_;
  std::FILE* f_ = nullptr;
};

// zlib's gzread over a stream that may start after an attached NRRD header.
class GzipReader {
public:
  GzipReader(const std::string& path, uint64_t start) : path_(path) {
    int fd = ::open(path.c_str(), O_RDONLY);
    if (fd < 0) fail("cannot open '{}': {}", path, std::strerror(errno));
    if (::lseek(fd, off_t(start), SEEK_SET) < 0) {
      ::close(fd);
      fail("cannot seek to byte {} in '{}'", start, path);
    }
    g_ = gzdopen(fd, "rb");  // takes ownership of fd
    if (!g_) {
      ::close(fd);
      fail("cannot open gzip stream in '{}'", path);
    }
    gzbuffer(g_, 1 << 18);
  }
  ~GzipReader() { gzclose(g_); }
  // Returns the bytes actually read (short only at the end of the stream).
  uint64_t read(unsigned char* dst, uint64_t bytes) {
    uint64_t done = 0;
    while (done < bytes) {
      unsigned want = unsigned(std::min<uint64_t>(bytes - done, 1u << 30));
      int r = gzread(g_, dst + done, want);
      if (r < 0) {
        int code = 0;
        const char* msg = gzerror(g_, &code);
        fail("'{}': corrupt gzip data after {} decompressed bytes ({})", path_, total_ + done, msg ? msg : "?");
      }
      if (r == 0) break;
      done += uint64_t(r);
    }
    total_ += done;
    return done;
  }
  // Reads (and drops) the rest of the stream, for the size message.
  uint64_t drain() {
    std::vector<unsigned char> tmp(1 << 18);
    while (read(tmp.data(), tmp.size()) == tmp.size()) {
    }
    return total_;
  }
  uint64_t total() const { return total_; }

private:
  std::string path_;
  gzFile g_ = nullptr;
  uint64_t total_ = 0;
};

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

struct Partial {
  double lo = std::numeric_limits<double>::infinity();
  double hi = -std::numeric_limits<double>::infinity();
  uint64_t nonfinite = 0;
  uint64_t first_nonfinite = std::numeric_limits<uint64_t>::max();
  void merge(const Partial& o) {
    lo = std::min(lo, o.lo);
    hi = std::max(hi, o.hi);
    nonfinite += o.nonfinite;
    first_nonfinite = std::min(first_nonfinite, o.first_nonfinite);
  }
};

// Stores v - pivot as float: relative to a value inside the data, float keeps ~7 significant
// digits of the *range* even for float64/int32 data far from zero, so one pass suffices.
template <typename T>
void convert_chunk(const unsigned char* buf, int64_t n, uint64_t first, bool swap, double& pivot, bool& pivot_set,
                   float* out, Partial& acc) {
  constexpr size_t S = sizeof(T);
  if (!pivot_set) {
    for (int64_t i = 0; i < n; ++i) {
      double v = element<T>(buf + i * S, swap);
      if (std::isfinite(v)) {
        pivot = v;
        pivot_set = true;
        break;
      }
    }
  }
  const double pv = pivot;
  constexpr int64_t grain = 1 << 16;
  std::vector<Partial> parts(size_t((n + grain - 1) / grain));
  parallel_for_range(n, grain, [&](int64_t b, int64_t e) {
    Partial p;
    for (int64_t i = b; i < e; ++i) {
      double v = element<T>(buf + i * S, swap);
      if constexpr (std::is_floating_point_v<T>) {
        if (!std::isfinite(v)) {
          if (p.nonfinite++ == 0) p.first_nonfinite = first + uint64_t(i);
          out[i] = float(v);  // NaN / +-Inf kept as markers for the normalisation pass
          continue;
        }
      }
      p.lo = std::min(p.lo, v);
      p.hi = std::max(p.hi, v);
      out[i] = float(std::clamp(v - pv, -double(FLT_MAX), double(FLT_MAX)));
    }
    parts[size_t(b / grain)] = p;
  });
  for (auto& p : parts) acc.merge(p);
}

void convert_any(DType t, const unsigned char* buf, int64_t n, uint64_t first, bool swap, double& pivot,
                 bool& pivot_set, float* out, Partial& acc) {
  switch (t) {
    case DType::Int8: return convert_chunk<int8_t>(buf, n, first, swap, pivot, pivot_set, out, acc);
    case DType::UInt8: return convert_chunk<uint8_t>(buf, n, first, swap, pivot, pivot_set, out, acc);
    case DType::Int16: return convert_chunk<int16_t>(buf, n, first, swap, pivot, pivot_set, out, acc);
    case DType::UInt16: return convert_chunk<uint16_t>(buf, n, first, swap, pivot, pivot_set, out, acc);
    case DType::Int32: return convert_chunk<int32_t>(buf, n, first, swap, pivot, pivot_set, out, acc);
    case DType::UInt32: return convert_chunk<uint32_t>(buf, n, first, swap, pivot, pivot_set, out, acc);
    case DType::Float32: return convert_chunk<float>(buf, n, first, swap, pivot, pivot_set, out, acc);
    case DType::Float64: return convert_chunk<double>(buf, n, first, swap, pivot, pivot_set, out, acc);
  }
}

}  // namespace

Volume load_volume(const VolumeDesc& desc, const LoadOptions& opts) {
  const Int3 d = desc.dims;
  if (d.x <= 0 || d.y <= 0 || d.z <= 0 || d.x > (1 << 30) || d.y > (1 << 30) || d.z > (1 << 30) ||
      d.count() > (uint64_t(1) << 40))
    fail("'{}': invalid dims {}", desc.path, detail::dims_string(d));
  const uint64_t n = d.count();
  const size_t esize = dtype_size(desc.dtype);
  const uint64_t frame = n * esize;

  Volume vol;
  vol.dims = d;
  vol.source_dtype = desc.dtype;
  vol.spacing = desc.spacing;
  try {
    vol.data.resize(n);
  } catch (const std::bad_alloc&) {
    fail("cannot allocate {:.1f} GiB for '{}' ({} voxels)", double(n) * 4 / (1 << 30), desc.path, n);
  }

  const bool swap = desc.big_endian != (std::endian::native == std::endian::big);
  bool pivot_set = desc.range_lo || desc.range_hi;
  double pivot = desc.range_lo ? *desc.range_lo : desc.range_hi.value_or(0.0);
  Partial acc;
  const uint64_t chunk = uint64_t(1) << 22;
  std::vector<unsigned char> buf(size_t(std::max<uint64_t>(std::min(n, chunk) * esize, 1 << 16)));

  if (desc.encoding == "gzip") {
    GzipReader in(desc.path, desc.gzip_start);
    // Expected decompressed size: the byte skip plus every timestep.
    const uint64_t base = desc.offset - uint64_t(desc.timestep) * frame;
    const uint64_t expected = base + uint64_t(desc.n_timesteps) * frame;
    auto size_error = [&]() {
      fail("'{}' decompresses to {} bytes, expected {} ({} {} + byte skip {})", desc.path, in.drain(), expected,
           detail::dims_string(d, desc.n_timesteps), dtype_name(desc.dtype), base);
    };
    for (uint64_t skip = desc.offset; skip > 0;) {
      uint64_t m = std::min<uint64_t>(skip, buf.size());
      if (in.read(buf.data(), m) != m) size_error();
      skip -= m;
    }
    for (uint64_t i0 = 0; i0 < n; i0 += chunk) {
      uint64_t m = std::min(chunk, n - i0);
      if (in.read(buf.data(), m * esize) != m * esize) size_error();
      convert_any(desc.dtype, buf.data(), int64_t(m), i0, swap, pivot, pivot_set, vol.data.data() + i0, acc);
    }
    if (in.drain() != expected) size_error();
  } else {
    RawReader in(desc.path, desc.offset);
    for (uint64_t i0 = 0; i0 < n; i0 += chunk) {
      uint64_t m = std::min(chunk, n - i0);
      in.read_exact(buf.data(), m * esize);
      convert_any(desc.dtype, buf.data(), int64_t(m), i0, swap, pivot, pivot_set, vol.data.data() + i0, acc);
    }
  }

  if (acc.nonfinite > 0 && opts.non_finite == NonFinitePolicy::Error) {
    uint64_t i = acc.first_nonfinite, xy = uint64_t(d.x) * uint64_t(d.y);
    fail("'{}' contains {} NaN/Inf values (first at voxel ({},{},{})); use --nan zero|clamp", desc.path,
         acc.nonfinite, i % uint64_t(d.x), (i / uint64_t(d.x)) % uint64_t(d.y), i / xy);
  }

  // Range: explicit ends win, the data's finite min/max fill in the rest (B.1).
  const bool any_finite = acc.lo <= acc.hi;
  double lo = desc.range_lo ? *desc.range_lo : (any_finite ? acc.lo : (desc.range_hi ? *desc.range_hi : 0.0));
  double hi = desc.range_hi ? *desc.range_hi : (any_finite ? acc.hi : lo);
  if (!std::isfinite(lo) || !std::isfinite(hi)) fail("'{}': value range must be finite", desc.path);
  if (desc.range_lo && desc.range_hi && lo > hi) fail("'{}': invalid value range [{}, {}] (lo > hi)", desc.path, lo, hi);
  if (hi < lo) hi = lo;  // one explicit end beyond all data: everything maps to one end
  vol.lo = lo;
  vol.hi = hi;

  const double shift = lo - pivot;
  const double inv = hi > lo ? 1.0 / (hi - lo) : 0.0;  // constant volume -> all 0
  const bool clamp_inf = opts.non_finite == NonFinitePolicy::Clamp;
  float* data = vol.data.data();
  parallel_for_range(int64_t(n), 1 << 16, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) {
      float s = data[i];
      if (std::isfinite(s)) {
        double u = (double(s) - shift) * inv;
        data[i] = u <= 0 ? 0.f : (u >= 1 ? 1.f : float(u));
      } else {
        data[i] = (clamp_inf && s > 0 && inv > 0) ? 1.f : 0.f;  // NaN and -Inf -> lo, +Inf -> hi (clamp) or lo (zero)
      }
    }
  });
  return vol;
}

}  // namespace vnr
