// Procedural test volumes with closed forms (Marschner-Lobb) or cheap deterministic structure at
// every scale (value noise), streamed to disk slab by slab.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <memory>
#include <numbers>
#include <vector>
#include "vnr/error.h"
#include "vnr/core/parallel.h"
#include "vnr/fileio.h"
#include "vnr/json.h"
#include "vnr/volume_writer.h"

namespace vnr {
namespace {

enum class Kind { MarschnerLobb, Noise };

Kind parse_kind(const std::string& kind) {
  if (kind == "marschner-lobb" || kind == "marschner_lobb" || kind == "ml") return Kind::MarschnerLobb;
  if (kind == "noise") return Kind::Noise;
  fail("unknown synthetic volume '{}' (allowed: marschner-lobb, noise)", kind);
}

// Marschner & Lobb 1994, alpha = 0.25, f_M = 6, on [-1,1]^3; values span [0,1].
double marschner_lobb(double x, double y, double z) {
  constexpr double pi = std::numbers::pi, alpha = 0.25, f_m = 6.0;
  double r = std::sqrt(x * x + y * y);
  double rho_r = std::cos(2 * pi * f_m * std::cos(pi * r / 2));
  return (1 - std::sin(pi * z / 2) + alpha * (1 + rho_r)) / (2 * (1 + alpha));
}

inline uint64_t fmix64(uint64_t h) {  // MurmurHash3 finaliser: full avalanche in 5 operations
  h ^= h >> 33;
  h *= 0xff51afd7ed558ccdULL;
  h ^= h >> 33;
  h *= 0xc4ceb9fe1a85ec53ULL;
  h ^= h >> 33;
  return h;
}

inline double lattice(int64_t i, int64_t j, int64_t k, uint64_t key) {
  uint64_t h = key ^ (uint64_t(i) * 0x9E3779B97F4A7C15ULL + uint64_t(j) * 0xC2B2AE3D27D4EB4FULL +
                      uint64_t(k) * 0x165667B19E3779F9ULL);
  return double(fmix64(h) >> 11) * 0x1p-53;  // [0,1)
}

inline double fade(double t) { return t * t * t * (t * (t * 6 - 15) + 10); }  // C2-smooth

// Six octaves of trilinearly blended lattice values (4 cells per unit at the coarsest, doubling),
// amplitudes halving; normalised by the amplitude sum so the result stays in [0,1].
// Evaluated a row of x positions at a time: per octave the (y,z) blend of each lattice column is
// computed once and shared by all points of the row, which is much cheaper than point by point.
// A single point is a row of one, so both paths give bit-identical values.
void value_noise_row(const float* ux, int64_t n, float uy, float uz, uint64_t seed, float* out) {
  std::vector<double> sum(size_t(n), 0.0), column;
  double amp_sum = 0, amp = 1, freq = 4;
  const auto [min_x, max_x] = std::minmax_element(ux, ux + n);
  for (int o = 0; o < 6; ++o) {
    uint64_t key = fmix64(seed * 0x9E3779B97F4A7C15ULL + uint64_t(o + 1) * 0xD1B54A32D192ED03ULL);
    double py = double(uy) * freq, pz = double(uz) * freq;
    double fy = std::floor(py), fz = std::floor(pz);
    int64_t iy = int64_t(fy), iz = int64_t(fz);
    double ty = fade(py - fy), tz = fade(pz - fz);
    int64_t ix_lo = int64_t(std::floor(double(*min_x) * freq)), ix_hi = int64_t(std::floor(double(*max_x) * freq)) + 1;
    column.resize(size_t(ix_hi - ix_lo + 1));
    for (int64_t ix = ix_lo; ix <= ix_hi; ++ix) {
      double c0 = lattice(ix, iy, iz, key), c1 = lattice(ix, iy + 1, iz, key);
      double c2 = lattice(ix, iy, iz + 1, key), c3 = lattice(ix, iy + 1, iz + 1, key);
      double a = c0 + (c1 - c0) * ty, b = c2 + (c3 - c2) * ty;
      column[size_t(ix - ix_lo)] = a + (b - a) * tz;
    }
    for (int64_t i = 0; i < n; ++i) {
      double px = double(ux[i]) * freq, fx = std::floor(px);
      size_t k = size_t(int64_t(fx) - ix_lo);
      double a = column[k], b = column[k + 1];
      sum[size_t(i)] += amp * (a + (b - a) * fade(px - fx));
    }
    amp_sum += amp;
    amp *= 0.5;
    freq *= 2;
  }
  for (int64_t i = 0; i < n; ++i) out[i] = float(sum[size_t(i)] / amp_sum);
}

float eval(Kind k, float ux, float uy, float uz, uint64_t seed) {
  if (k == Kind::MarschnerLobb) return float(marschner_lobb(2.0 * ux - 1, 2.0 * uy - 1, 2.0 * uz - 1));
  float v;
  value_noise_row(&ux, 1, uy, uz, seed, &v);
  return v;
}

// Voxel centres (i + 0.5)/N, rounded to float exactly as a caller of synth_value would, moved to
// where timestep t samples the field (t = 0: unchanged).
struct Centres {
  std::vector<float> x, y, z;
};

// Timestep t of a series samples the field at u - t * velocity: the field drifts by `velocity` (in
// units of the volume's extent) per timestep.
constexpr double kSeriesVelocity[3] = {0.02, 0.015, 0.01};

inline float series_coord(float u, int t, int axis) { return float(double(u) - double(t) * kSeriesVelocity[axis]); }

Centres centres(Int3 dims, int t) {
  auto axis = [t](int64_t n, int a) {
    std::vector<float> c(static_cast<size_t>(n));
    for (int64_t i = 0; i < n; ++i) c[size_t(i)] = series_coord(float((double(i) + 0.5) / double(n)), t, a);
    return c;
  };
  return Centres{axis(dims.x, 0), axis(dims.y, 1), axis(dims.z, 2)};
}

// Evaluates the field on the grid of centres in z-slabs of about 4 M voxels, handing each slab
// (x fastest) to sink(values, n_slices).
template <typename Sink>
void for_each_slab(Kind k, Int3 dims, const Centres& c, uint64_t seed, Sink&& sink) {
  const int64_t slice = dims.x * dims.y;
  const int64_t slab = std::max<int64_t>(1, (int64_t(1) << 22) / slice);
  std::vector<float> buf(size_t(std::min(slab, dims.z) * slice));
  for (int64_t z0 = 0; z0 < dims.z; z0 += slab) {
    const int64_t nz = std::min(slab, dims.z - z0);
    parallel_for_range(nz * dims.y, 16, [&](int64_t b, int64_t e) {
      for (int64_t row = b; row < e; ++row) {  // row = y + ny * (z - z0)
        int64_t y = row % dims.y, z = z0 + row / dims.y;
        float* out = buf.data() + row * dims.x;
        if (k == Kind::Noise) {
          value_noise_row(c.x.data(), dims.x, c.y[size_t(y)], c.z[size_t(z)], seed, out);
        } else {
          for (int64_t x = 0; x < dims.x; ++x) out[x] = eval(k, c.x[size_t(x)], c.y[size_t(y)], c.z[size_t(z)], seed);
        }
      }
    });
    sink(static_cast<const float*>(buf.data()), nz);
  }
}

}  // namespace

float synth_value(const std::string& kind, float ux, float uy, float uz, uint64_t seed) {
  return eval(parse_kind(kind), ux, uy, uz, seed);
}

std::vector<std::string> synth_output_files(const std::string& out_json) {
  if (extension_of(out_json) != ".json" || basename_of(strip_extension(out_json)).empty())
    fail("synthetic volume output '{}' must be a .json sidecar path (the data goes beside it as .raw)", out_json);
  return volume_output_files(strip_extension(out_json) + ".raw");
}

void synth_volume(const std::string& kind, Int3 dims, const std::string& out_json, uint64_t seed) {
  Kind k = parse_kind(kind);
  const std::string raw = synth_output_files(out_json)[0];
  if (dims.x <= 0 || dims.y <= 0 || dims.z <= 0 || dims.x > (1 << 30) || dims.y > (1 << 30) ||
      dims.count() > (uint64_t(1) << 40))
    fail("invalid dims {}x{}x{} for a synthetic volume", dims.x, dims.y, dims.z);
  VolumeWriter w(raw, dims, DType::Float32);
  const Centres c = centres(dims, 0);
  for_each_slab(k, dims, c, seed, [&](const float* buf, int64_t nz) { w.write_slices(buf, nz); });
  w.commit();
}

// ---- time series ----

float synth_series_value(const std::string& kind, int timestep, float ux, float uy, float uz, uint64_t seed) {
  return eval(parse_kind(kind), series_coord(ux, timestep, 0), series_coord(uy, timestep, 1),
              series_coord(uz, timestep, 2), seed);
}

std::vector<std::string> synth_series_output_files(const std::string& out_json, int timesteps, bool file_list) {
  const std::string raw = synth_output_files(out_json)[0];  // validates out_json
  if (!file_list) return {raw, out_json};
  std::vector<std::string> files;
  for (int t = 0; t < timesteps; ++t) files.push_back(fmt::format("{}_t{:04d}.raw", strip_extension(out_json), t));
  files.push_back(out_json);
  return files;
}

void synth_series(const std::string& kind, Int3 dims, int timesteps, const std::string& out_json, uint64_t seed,
                  bool file_list) {
  Kind k = parse_kind(kind);
  if (timesteps <= 0 || timesteps > (1 << 20)) fail("a synthetic series needs 1 to 2^20 timesteps, got {}", timesteps);
  const std::vector<std::string> files = synth_series_output_files(out_json, timesteps, file_list);
  if (dims.x <= 0 || dims.y <= 0 || dims.z <= 0 || dims.x > (1 << 30) || dims.y > (1 << 30) ||
      dims.count() > (uint64_t(1) << 40) || dims.count() * uint64_t(timesteps) > (uint64_t(1) << 40))
    fail("invalid dims {}x{}x{}x{} for a synthetic series", dims.x, dims.y, dims.z, timesteps);

  // float32, little endian on disk; all data files are committed before the sidecar that names them.
  std::vector<std::unique_ptr<AtomicFile>> out;
  double lo = 1e308, hi = -1e308;
  std::vector<unsigned char> bytes;
  for (int t = 0; t < timesteps; ++t) {
    if (t == 0 || file_list) out.push_back(std::make_unique<AtomicFile>(files[file_list ? size_t(t) : 0]));
    AtomicFile& f = *out.back();
    for_each_slab(k, dims, centres(dims, t), seed, [&](const float* buf, int64_t nz) {
      const size_t n = size_t(nz * dims.x * dims.y);
      for (size_t i = 0; i < n; ++i) {
        lo = std::min(lo, double(buf[i]));
        hi = std::max(hi, double(buf[i]));
      }
      bytes.resize(n * 4);
      std::memcpy(bytes.data(), buf, n * 4);
      if constexpr (std::endian::native == std::endian::big)
        for (size_t i = 0; i < n; ++i) std::reverse(bytes.begin() + std::ptrdiff_t(4 * i), bytes.begin() + std::ptrdiff_t(4 * i + 4));
      f.write(bytes.data(), bytes.size());
    });
  }
  Json side;
  if (file_list) {
    side["file"] = Json::array();
    for (int t = 0; t < timesteps; ++t) side["file"].push_back(basename_of(files[size_t(t)]));
    side["dims"] = {dims.x, dims.y, dims.z};
  } else {
    side["file"] = basename_of(files[0]);
    side["dims"] = {dims.x, dims.y, dims.z, timesteps};
  }
  side["dtype"] = "float32";
  side["byte_order"] = "little";
  side["spacing"] = {1.0, 1.0, 1.0};
  side["value_range"] = {lo, hi};  // the min/max over all timesteps: every timestep normalises alike
  for (auto& f : out) f->commit();
  write_file_atomic(out_json, side.dump(2) + "\n");
}

}  // namespace vnr
