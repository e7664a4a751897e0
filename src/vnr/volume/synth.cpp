// Procedural test volumes with closed forms (Marschner-Lobb) or cheap deterministic structure at
// every scale (value noise), streamed to disk slab by slab.
#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>
#include "vnr/core/error.h"
#include "vnr/core/parallel.h"
#include "vnr/core/fileio.h"
#include "vnr/volume/writer.h"

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
// computed once and shared by all points of the row, which makes a volume ~10x cheaper than
// point by point. A single point is a row of one, so both paths give bit-identical values.
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

  // Voxel centres (i + 0.5)/N, rounded to float exactly as a caller of synth_value would.
  auto centres = [](int64_t n) {
    std::vector<float> c(static_cast<size_t>(n));
    for (int64_t i = 0; i < n; ++i) c[size_t(i)] = float((double(i) + 0.5) / double(n));
    return c;
  };
  const std::vector<float> cx = centres(dims.x), cy = centres(dims.y), cz = centres(dims.z);
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
          value_noise_row(cx.data(), dims.x, cy[size_t(y)], cz[size_t(z)], seed, out);
        } else {
          for (int64_t x = 0; x < dims.x; ++x) out[x] = eval(k, cx[size_t(x)], cy[size_t(y)], cz[size_t(z)], seed);
        }
      }
    });
    w.write_slices(buf.data(), nz);
  }
  w.commit();
}

}  // namespace vnr
