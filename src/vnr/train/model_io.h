#pragma once
#include <memory>
#include <optional>
#include <string>
#include "vnr/nn/model_file.h"
#include "vnr/nn/network.h"
#include "vnr/volume/value_range_grid.h"
#include "vnr/volume/volume.h"

namespace vnr {

// A network together with what it represents: the bridge between the in-memory Network and the
// model files.
struct Model {
  std::unique_ptr<Network> net;
  Int3 dims;
  DType source_dtype = DType::Float32;
  double lo = 0, hi = 1;
  Json training;  // summary written by `vnr train`
  std::optional<ValueRangeGrid> macrocells;  // value ranges built online while training (or imported)
  uint64_t param_bytes() const { return net->n_params() * 2; }  // fp16, as stored
};

// Writes .vnr, or instantvnr's BSON when the path ends in .bson or .json (instantvnr names its
// BSON files params.json).
void save_model(const std::string& path, const Model& m);
Model load_model(const std::string& path);
bool is_instantvnr_path(const std::string& path);

// Evaluation against the ground truth at voxel centres (compat.md B.4).
struct EvalResult {
  double psnr = 0, ssim = 0, mse = 0;
  double max_abs_error = 0;           // normalised units
  double max_abs_error_original = 0;  // original units
  double decode_seconds = 0;
};
EvalResult evaluate(const Network& net, const Volume& vol, bool with_ssim = true);

// Decodes the network at voxel centres of `dims` for z-slices [z0, z1) into out (normalised units).
void decode_slices(const Network& net, Int3 dims, int64_t z0, int64_t z1, float* out);

// Sizes the grid of `config` (log2_hashmap_size, and n_levels if needed) so the fp16 model is about
// volume_bytes / ratio. Returns the adjusted config; `note` describes the choice.
Json size_config_for_ratio(const Json& config, uint64_t volume_bytes, double ratio, std::string* note);

}  // namespace vnr
