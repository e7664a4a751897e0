#include "vnr/volume_writer.h"
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <vector>
#include "vnr/error.h"
#include "vnr/json.h"

namespace vnr {
namespace {

bool is_nrrd_path(const std::string& p) { return extension_of(p) == ".nrrd"; }

// NRRD spells the floating types "float"/"double"; the integer names are vnr's own.
const char* nrrd_type(DType t) {
  if (t == DType::Float32) return "float";
  if (t == DType::Float64) return "double";
  return dtype_name(t);
}

// Little-endian bytes of one value of type T.
template <typename T>
void put(unsigned char* dst, T v) {
  std::memcpy(dst, &v, sizeof(T));
  if constexpr (std::endian::native == std::endian::big) std::reverse(dst, dst + sizeof(T));
}

// Writes to_stored_value(v); returns the stored value.
template <typename T>
double store(unsigned char* dst, float v) {
  const T stored = to_stored_value<T>(v);
  put<T>(dst, stored);
  return double(stored);
}

// Shortest text that reads back as the same double (fmt), which is also valid JSON for finite values.
std::string json_number(double v) {
  if (!std::isfinite(v)) fail("cannot write a non-finite number ({}) to a JSON sidecar", v);
  return fmt::format("{}", v);
}

}  // namespace

VolumeWriter::VolumeWriter(const std::string& path, Int3 dims, DType dtype, Vec3f spacing,
                           std::optional<std::pair<double, double>> value_range)
    : path_(path), dims_(dims), dtype_(dtype), spacing_(spacing), range_(value_range) {
  if (dims.x <= 0 || dims.y <= 0 || dims.z <= 0)
    fail("cannot write '{}': dims {}x{}x{} must all be positive", path, dims.x, dims.y, dims.z);
  if (!is_nrrd_path(path) && sidecar_path() == path)
    fail("cannot write '{}': a raw volume needs a data file name other than its .json sidecar", path);
  file_ = std::make_unique<AtomicFile>(path);
  // Nothing in the header depends on the data, so it goes first and the slices follow it.
  const std::string h = volume_file_header(path, dims, dtype, spacing);
  if (!h.empty()) file_->write(h);
}

std::string volume_file_header(const std::string& path, Int3 dims, DType dtype, Vec3f spacing) {
  if (!is_nrrd_path(path)) return {};
  std::string h = "NRRD0004\n# written by vnr\n";
  h += fmt::format("type: {}\ndimension: 3\nsizes: {} {} {}\nendian: little\nencoding: raw\n", nrrd_type(dtype),
                   dims.x, dims.y, dims.z);
  h += fmt::format("spacings: {} {} {}\n\n", spacing.x, spacing.y, spacing.z);
  return h;
}

std::pair<double, double> store_values(DType dtype, const float* values, int64_t n, unsigned char* out) {
  const size_t esize = dtype_size(dtype);
  double lo = 1e308, hi = -1e308;
  for (int64_t i = 0; i < n; ++i) {
    unsigned char* dst = out + i * esize;
    const float v = values[i];
    double s = 0;
    switch (dtype) {
      case DType::Int8: s = store<int8_t>(dst, v); break;
      case DType::UInt8: s = store<uint8_t>(dst, v); break;
      case DType::Int16: s = store<int16_t>(dst, v); break;
      case DType::UInt16: s = store<uint16_t>(dst, v); break;
      case DType::Int32: s = store<int32_t>(dst, v); break;
      case DType::UInt32: s = store<uint32_t>(dst, v); break;
      case DType::Float32: s = store<float>(dst, v); break;
      case DType::Float64: s = store<double>(dst, v); break;
    }
    if (std::isfinite(s)) lo = std::min(lo, s), hi = std::max(hi, s);
  }
  return {lo, hi};
}

std::string raw_sidecar_text(const std::string& path, Int3 dims, DType dtype, Vec3f spacing,
                             std::optional<std::pair<double, double>> r) {
  std::string j = "{\n";
  j += fmt::format("  \"file\": {},\n", Json(basename_of(path)).dump());
  j += fmt::format("  \"dims\": [{}, {}, {}],\n", dims.x, dims.y, dims.z);
  j += fmt::format("  \"dtype\": \"{}\",\n  \"byte_order\": \"little\",\n", dtype_name(dtype));
  // Spacing is float: printing the float (not its double widening) keeps 0.88 as "0.88".
  j += fmt::format("  \"spacing\": [{}, {}, {}]", spacing.x, spacing.y, spacing.z);
  if (r) j += fmt::format(",\n  \"value_range\": [{}, {}]", json_number(r->first), json_number(r->second));
  j += "\n}\n";
  return j;
}

std::vector<std::string> volume_output_files(const std::string& path) {
  if (is_nrrd_path(path)) return {path};
  return {path, strip_extension(path) + ".json"};
}

VolumeWriter::~VolumeWriter() = default;  // an uncommitted AtomicFile removes its temporary

std::string VolumeWriter::sidecar_path() const {
  return is_nrrd_path(path_) ? std::string() : strip_extension(path_) + ".json";
}

void VolumeWriter::write_slices(const float* values, int64_t n_slices) {
  if (!file_) fail("cannot write '{}': already committed", path_);
  if (n_slices < 0 || slices_written_ + n_slices > dims_.z)
    fail("cannot write '{}': {} more slices would exceed dims.z = {}", path_, n_slices, dims_.z);
  const size_t esize = dtype_size(dtype_);
  const int64_t n = dims_.x * dims_.y * n_slices;
  constexpr int64_t block = 1 << 16;
  std::vector<unsigned char> buf(size_t(std::min(n, block)) * esize);
  for (int64_t i0 = 0; i0 < n; i0 += block) {
    int64_t m = std::min(block, n - i0);
    const auto [lo, hi] = store_values(dtype_, values + i0, m, buf.data());
    seen_lo_ = std::min(seen_lo_, lo);
    seen_hi_ = std::max(seen_hi_, hi);
    file_->write(buf.data(), size_t(m) * esize);
  }
  slices_written_ += n_slices;
}

void VolumeWriter::commit() {
  if (!file_) fail("cannot write '{}': already committed", path_);
  if (slices_written_ != dims_.z)
    fail("cannot write '{}': {} of {} z-slices were written", path_, slices_written_, dims_.z);
  // Data first, then the sidecar that points at it: a reader never finds a dangling sidecar.
  file_->commit();
  file_.reset();
  if (is_nrrd_path(path_)) return;
  std::optional<std::pair<double, double>> r = range_;
  if (!r && seen_lo_ <= seen_hi_) r = std::make_pair(seen_lo_, seen_hi_);
  const std::string j = raw_sidecar_text(path_, dims_, dtype_, spacing_, r);
  write_file_atomic(sidecar_path(), j);
}

}  // namespace vnr
