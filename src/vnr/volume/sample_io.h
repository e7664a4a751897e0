#pragma once
// Internal to the volume layer: what every reader of volume samples shares — load_volume
// (load.cpp), the streaming readers (stream.cpp) and random access (raw_access.cpp) — so that all
// of them convert and normalise bit for bit alike (docs/semantics.md B.1). The functions that are not
// inline are defined in stream.cpp.
#include <algorithm>
#include <bit>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>
#include "vnr/core/parallel.h"
#include "vnr/volume/stream.h"
#include "vnr/volume/volume.h"

struct gzFile_s;  // zlib's gzFile

namespace vnr::detail {

class DatasetReader;  // dataset.h: HDF5 datasets and NetCDF variables

template <typename T>
struct TypeTag {
  using type = T;
};

// Calls f(TypeTag<T>{}) with the C++ type T of a sample of dtype t.
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

// The sample of type T at p, byte-swapped first if `swap`.
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

inline bool needs_swap(const VolumeDesc& d) { return d.big_endian != (std::endian::native == std::endian::big); }

// "'<path>': invalid dims ..." unless every extent is in [1, 2^30] and there are at most 2^40 voxels.
void check_dims(const VolumeDesc& desc);
// A normalisation range must be finite with lo <= hi.
void check_range(const VolumeDesc& desc, double lo, double hi);

// load_volume's normalisation with range [lo, hi], in its two steps. keep: a finite sample v is
// stored as float(v - pivot), which keeps ~7 significant digits of the *range* even for float64 or
// int32 data far from zero (pivot = a value inside the data); NaN/Inf are stored as themselves.
// map: a stored value s becomes u = clamp((double(s) - (lo - pivot)) / (hi - lo), 0, 1) in double;
// a constant volume maps to 0, NaN and -Inf to 0, +Inf to 1 under NonFinitePolicy::Clamp (else 0;
// Error is the caller's check). operator() does both steps for one sample.
struct PivotNormaliser {
  double pivot = 0, shift = 0, inv = 0;  // shift = lo - pivot; inv = 1 / (hi - lo), or 0
  bool clamp_inf = false;
  PivotNormaliser() = default;
  PivotNormaliser(double pivot_, double lo, double hi, NonFinitePolicy policy) { set(pivot_, lo, hi, policy); }
  void set(double pivot_, double lo, double hi, NonFinitePolicy policy) {
    pivot = pivot_;
    shift = lo - pivot;
    inv = hi > lo ? 1.0 / (hi - lo) : 0.0;
    clamp_inf = policy == NonFinitePolicy::Clamp;
  }
  static float keep(double v, double pivot) { return float(std::clamp(v - pivot, -double(FLT_MAX), double(FLT_MAX))); }
  float map(float s) const {
    if (!std::isfinite(s)) return (clamp_inf && s > 0 && inv > 0) ? 1.f : 0.f;
    double u = (double(s) - shift) * inv;
    return u <= 0 ? 0.f : (u >= 1 ? 1.f : float(u));
  }
  float operator()(double v) const { return map(std::isfinite(v) ? keep(v, pivot) : float(v)); }
};

// load_volume's pivot when the description fixes it (an explicit range end: lo, else hi). Returns
// false when it does not: the pivot is then the first finite sample in file order (find_pivot).
inline bool pivot_from_desc(const VolumeDesc& desc, double* pivot) {
  *pivot = desc.range_lo ? *desc.range_lo : desc.range_hi.value_or(0.0);
  return desc.range_lo || desc.range_hi;
}

// The first finite sample of the n in buf, if any.
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

// Finite min/max and non-finite count of a stretch of samples; merged in any order gives one result.
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

// Tallies the n samples of type T in buf (voxels first, first + 1, ... in file order), in parallel;
// when out != nullptr also stores them as PivotNormaliser's keep step does, with `pivot` (which must
// be final: samples before the first finite one do not use it).
template <typename T>
Tally convert(const unsigned char* buf, int64_t n, uint64_t first, bool swap, double pivot, float* out) {
  constexpr int64_t grain = int64_t(1) << 16;
  std::vector<Tally> parts(size_t(std::max<int64_t>(1, (n + grain - 1) / grain)));
  parallel_for_range(n, grain, [&](int64_t b, int64_t e) {
    Tally t;
    for (int64_t i = b; i < e; ++i) {
      double v = element<T>(buf + i * int64_t(sizeof(T)), swap);
      if constexpr (std::is_floating_point_v<T>) {
        if (!std::isfinite(v)) {
          if (t.nonfinite++ == 0) t.first_nonfinite = first + uint64_t(i);
          if (out) out[i] = float(v);
          continue;
        }
      }
      t.lo = std::min(t.lo, v);
      t.hi = std::max(t.hi, v);
      if (out) out[i] = PivotNormaliser::keep(v, pivot);
    }
    parts[size_t(b / grain)] = t;
  });
  Tally all;
  for (const Tally& t : parts) all.merge(t);
  return all;
}

// PivotNormaliser's map step over n stored values, in place, in parallel.
inline void map_in_place(const PivotNormaliser& norm, float* data, int64_t n) {
  parallel_for_range(n, int64_t(1) << 16, [&](int64_t b, int64_t e) {
    const PivotNormaliser nm = norm;
    for (int64_t i = b; i < e; ++i) data[i] = nm.map(data[i]);
  });
}

// load_volume's range rule (B.1): explicit ends of desc win, the data's finite min/max (t) fill in
// the rest; one explicit end beyond all the data maps everything to that end.
ValueRange resolve_range(const VolumeDesc& desc, const Tally& t);

// "'<path>' contains <count> NaN/Inf values (first at voxel (x,y,z)); use --nan zero|clamp".
[[noreturn]] void nonfinite_error(const VolumeDesc& desc, uint64_t count, uint64_t first);

// pread of exactly `bytes` at byte `at` of the open file fd (named `path` in errors); a short read
// means the file shrank since it was described.
void pread_exact(int fd, unsigned char* dst, size_t bytes, uint64_t at, const std::string& path);

// The samples of one timestep in file order, from a raw file, a gzip stream or an HDF5/NetCDF
// dataset (read as hyperslabs of whole z-slices, chunk-aligned), with load_volume's messages for
// short or corrupt data.
class SampleStream {
public:
  explicit SampleStream(const VolumeDesc& desc);
  ~SampleStream();
  SampleStream(const SampleStream&) = delete;
  SampleStream& operator=(const SampleStream&) = delete;

  void read(unsigned char* dst, uint64_t bytes);
  // After the last voxel: a gzip stream must hold exactly what the description says, which means
  // decompressing any later timesteps too.
  void finish();

private:
  void close();
  uint64_t gz_read(unsigned char* dst, uint64_t bytes);
  uint64_t gz_drain();
  uint64_t gz_base() const;
  uint64_t gz_expected() const;
  [[noreturn]] void gz_size_error();
  void dataset_read(unsigned char* dst, uint64_t bytes);

  const VolumeDesc& desc_;
  uint64_t frame_ = 0;
  std::FILE* f_ = nullptr;
  uint64_t pos_ = 0;
  gzFile_s* gz_ = nullptr;
  uint64_t gz_total_ = 0;
  std::unique_ptr<DatasetReader> dataset_;
  std::vector<unsigned char> slab_;      // dataset: whole z-slices [slab_begin_, slab_end_) in bytes
  uint64_t slab_begin_ = 0, slab_end_ = 0;
};

}  // namespace vnr::detail
