// HashGrid / DenseGrid / TiledGrid (docs/semantics.md A.2): the multi-resolution grid. Per-sample code
// is grid_encoding.h's VNR_HD functions; chunks go through the per-SIMD-target kernels of cpu_kernels.
#include <cmath>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/nn/cpu_kernels.h"
#include "vnr/nn/encoding.h"
#include "vnr/nn/json_get.h"
#include "vnr/nn/point_eval.h"

namespace vnr {
namespace {

const char* grid_otype(GridType t) {
  return t == GridType::Hash ? "HashGrid" : (t == GridType::Dense ? "DenseGrid" : "TiledGrid");
}
const char* interpolation_name(Interpolation i) {
  return i == Interpolation::Linear ? "Linear" : (i == Interpolation::Nearest ? "Nearest" : "Smoothstep");
}

// F features per level: fixed here, in the factory (make_grid_encoding), so no call below asks again.
template <int F>
class GridEncoding final : public Encoding {
public:
  explicit GridEncoding(const EncodingConfig& e) : cfg_(e), grid_(make_grid_layout(e)) {}
  uint32_t output_width() const override { return grid_.n_levels * F; }
  uint32_t min_alignment() const override { return F; }
  float pad_value() const override { return 0.0f; }
  uint64_t n_params() const override { return grid_.n_params(); }
  const GridLayout* grid() const override { return &grid_; }

  void forward(const float* x, const float* y, const float* z, int n, const uint16_t* params,
               float* X0) const override {
    kernels::grid_encode<F>(grid_, params, x, y, z, n, X0);
  }
  uint32_t n_backward_parts() const override { return grid_.n_levels; }
  void backward(uint32_t level, const float* x, const float* y, const float* z, int64_t n, const float* dEnc,
                uint32_t in_pad, int chunk, float* grad) const override {
    kernels::grid_backward_level<F>(grid_, level, x, y, z, n, dEnc, in_pad, chunk, grad);
  }

  void encode_point(const float xyz[3], const uint16_t* params, float* out) const override {
    for (uint32_t l = 0; l < grid_.n_levels; ++l)
      grid_level_forward<F>(grid_.levels[l], grid_.interpolation, params, xyz[0], xyz[1], xyz[2], out + l * F, 1);
  }
  void encode_point_input_grad(const float xyz[3], const uint16_t* params, float* jac) const override {
    float tmp[F * 3];
    for (uint32_t l = 0; l < grid_.n_levels; ++l) {
      grid_level_input_grad<F>(grid_.levels[l], grid_.interpolation, params, xyz[0], xyz[1], xyz[2], tmp);
      for (int f = 0; f < F; ++f)
        for (int d = 0; d < 3; ++d) jac[(l * F + f) * 3 + d] = tmp[f * 3 + d];
    }
  }
  void select_point_kernels(const PointEvalData& d, PointEvalKernels* k) const override {
    vnr::select_point_kernels<F>(d, k);
  }

  Json to_json() const override {
    return {{"otype", grid_otype(cfg_.grid_type)},
            {"n_levels", cfg_.n_levels},
            {"n_features_per_level", cfg_.n_features_per_level},
            {"log2_hashmap_size", cfg_.log2_hashmap_size},
            {"base_resolution", cfg_.base_resolution},
            {"per_level_scale", cfg_.per_level_scale},
            {"interpolation", interpolation_name(cfg_.interpolation)}};
  }

private:
  EncodingConfig cfg_;
  GridLayout grid_;
};

void parse_grid(const std::string& lo, const Json& j, EncodingConfig& e) {
  const char* w = "encoding";
  e.type = EncodingType::Grid;
  std::string type = lo == "densegrid" ? "dense" : (lo == "tiledgrid" ? "tiled" : "hash");
  type = to_lower(json_get<std::string>(j, "type", type, w));
  if (type == "hash") e.grid_type = GridType::Hash;
  else if (type == "dense") e.grid_type = GridType::Dense;
  else if (type == "tiled" || type == "tile") e.grid_type = GridType::Tiled;
  else fail("encoding: unsupported grid type '{}' (allowed: Hash, Dense, Tiled)", type);
  if (j.contains("n_levels") && j.contains("n_features"))
    fail("encoding: give either 'n_levels' or 'n_features', not both");
  e.n_features_per_level = json_get<uint32_t>(j, "n_features_per_level", 2u, w);
  if (e.n_features_per_level != 1 && e.n_features_per_level != 2 && e.n_features_per_level != 4 &&
      e.n_features_per_level != 8)
    fail("encoding: n_features_per_level must be 1, 2, 4 or 8, got {}", e.n_features_per_level);
  if (j.contains("n_features")) {
    uint32_t nf = json_get<uint32_t>(j, "n_features", 32u, w);
    if (nf % e.n_features_per_level) fail("encoding: n_features must be a multiple of n_features_per_level");
    e.n_levels = nf / e.n_features_per_level;
  } else {
    e.n_levels = json_get<uint32_t>(j, "n_levels", 16u, w);
  }
  if (e.n_levels < 1 || e.n_levels > 32) fail("encoding: n_levels must be in 1..32, got {}", e.n_levels);
  e.log2_hashmap_size = json_get<uint32_t>(j, "log2_hashmap_size", 19u, w);
  if (e.log2_hashmap_size < 1 || e.log2_hashmap_size > 30)
    fail("encoding: log2_hashmap_size must be in 1..30, got {} (a table of 2^{} entries per level exceeds the "
         "limit of 2^30)",
         e.log2_hashmap_size, e.log2_hashmap_size);
  e.base_resolution = json_get<uint32_t>(j, "base_resolution", 16u, w);
  if (e.base_resolution < 1) fail("encoding: base_resolution must be at least 1");
  e.per_level_scale = json_get<float>(j, "per_level_scale", 2.0f, w);
  if (!(e.per_level_scale >= 1.0f) || !std::isfinite(e.per_level_scale))
    fail("encoding: per_level_scale must be a finite number >= 1");
  std::string interp = to_lower(json_get<std::string>(j, "interpolation", "Linear", w));
  if (interp == "linear") e.interpolation = Interpolation::Linear;
  else if (interp == "nearest") e.interpolation = Interpolation::Nearest;
  else if (interp == "smoothstep") e.interpolation = Interpolation::Smoothstep;
  else fail("encoding: unsupported interpolation '{}' (allowed: Nearest, Linear, Smoothstep)", interp);
}

// The one place a grid's features per level become the template F of its CPU kernels (parse_grid allows
// these four).
std::unique_ptr<Encoding> make_grid_encoding(const EncodingConfig& e) {
  std::unique_ptr<Encoding> enc;
  with_feature_count(e.n_features_per_level, [&](auto F) { enc = std::make_unique<GridEncoding<F()>>(e); });
  if (!enc) fail("encoding: n_features_per_level must be 1, 2, 4 or 8, got {}", e.n_features_per_level);
  return enc;
}

}  // namespace
}  // namespace vnr

VNR_ENCODING_REGISTRAR(grid) {
  registry.add({"Grid", {"HashGrid", "DenseGrid", "TiledGrid", "Grid"}, 0, parse_grid,
                make_grid_encoding});
}
