#include "vnr/train/model_io.h"
#include <chrono>
#include <cmath>
#include "vnr/core/error.h"
#include "vnr/core/fileio.h"
#include "vnr/core/progress.h"
#include "vnr/volume/metrics.h"

namespace vnr {

bool is_instantvnr_path(const std::string& path) {
  const std::string e = extension_of(path);
  return e == ".bson" || e == ".json";
}

void save_model(const std::string& path, const Model& m) {
  ModelFile f;
  f.config = m.net->config_json();
  f.dims = m.dims;
  f.source_dtype = m.source_dtype;
  f.lo = m.lo;
  f.hi = m.hi;
  f.params = m.net->params_half();
  f.training = m.training;
  if (m.macrocells) {
    f.macrocell_dims = m.macrocells->cells;
    f.macrocell_ranges = m.macrocells->to_pairs();
  }
  if (is_instantvnr_path(path)) write_instantvnr(path, f);
  else write_vnr(path, f);
}

Model load_model(const std::string& path) {
  ModelFile f = read_model(path);
  Model m;
  m.net = std::make_unique<Network>(f.config);
  if (f.params.size() != m.net->n_params())
    fail("'{}': the file holds {} parameters but its configuration needs {}", path, f.params.size(),
         m.net->n_params());
  m.net->set_params_half(f.params);
  m.dims = f.dims;
  m.source_dtype = f.source_dtype;
  m.lo = f.lo;
  m.hi = f.hi;
  m.training = f.training;
  if (!(f.macrocell_dims == Int3{}) && f.dims.count() > 0) {
    try {
      m.macrocells = ValueRangeGrid::from_pairs(f.dims, f.macrocell_dims, f.macrocell_ranges);
    } catch (const Error& e) {
      fail("'{}': {}", path, e.what());
    }
  }
  return m;
}

void decode_slices(const Network& net, Int3 dims, int64_t z0, int64_t z1, float* out) {
  const int64_t nx = dims.x, ny = dims.y, nz = dims.z;
  const int64_t n = nx * ny * (z1 - z0);
  net.infer_fn(
      n,
      [&](int64_t i, float* x, float* y, float* z) {
        int64_t ix = i % nx, iy = (i / nx) % ny, iz = z0 + i / (nx * ny);
        *x = (float(ix) + 0.5f) / float(nx);
        *y = (float(iy) + 0.5f) / float(ny);
        *z = (float(iz) + 0.5f) / float(nz);
      },
      out);
}

EvalResult evaluate(const Network& net, const Volume& vol, bool with_ssim) {
  EvalResult r;
  std::vector<float> dec(vol.data.size());
  auto t0 = std::chrono::steady_clock::now();
  decode_slices(net, vol.dims, 0, vol.dims.z, dec.data());
  r.decode_seconds = seconds_since(t0);
  ErrorStats e = error_stats(vol.data.data(), dec.data(), vol.dims);
  r.psnr = e.psnr;
  r.mse = e.mse;
  r.max_abs_error = e.max_abs_error;
  r.max_abs_error_original = e.max_abs_error * (vol.hi - vol.lo);
  if (with_ssim) r.ssim = ssim3d(vol.data.data(), dec.data(), vol.dims);
  return r;
}

Json size_config_for_ratio(const Json& config, uint64_t volume_bytes, double ratio, std::string* note) {
  if (!(ratio > 0)) fail("--target-ratio must be positive, got {}", ratio);
  const double target = double(volume_bytes) / ratio;
  Json base = ModelConfig::from_json(config).to_json();
  if (base["encoding"]["otype"] != "HashGrid")
    fail("--target-ratio needs a HashGrid encoding (the config has {})", base["encoding"]["otype"].dump());
  Json best;
  double best_err = 1e300;
  uint64_t best_bytes = 0;
  const uint32_t L0 = base["encoding"]["n_levels"].get<uint32_t>();
  for (uint32_t L = L0; L >= 1; --L)
    for (uint32_t t = 8; t <= 24; ++t) {
      Json c = base;
      c["encoding"]["n_levels"] = L;
      c["encoding"]["log2_hashmap_size"] = t;
      uint64_t bytes = count_params(c) * 2;
      // Prefer keeping all levels: penalise each dropped level by a factor 1.5 in size error.
      double err = std::fabs(std::log(double(bytes) / target)) + 0.4 * (L0 - L);
      if (err < best_err) best_err = err, best = c, best_bytes = bytes;
    }
  if (note)
    *note = fmt::format("--target-ratio {}: {} levels, 2^{} table, {:.2f} MiB model (ratio {:.1f})", ratio,
                        best["encoding"]["n_levels"].get<uint32_t>(),
                        best["encoding"]["log2_hashmap_size"].get<uint32_t>(), best_bytes / 1048576.0,
                        double(volume_bytes) / best_bytes);
  return best;
}

}  // namespace vnr
