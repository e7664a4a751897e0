#pragma once
// A Network with what it represents, and its files (.vnr, instantvnr BSON).
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>
#include "vnr/dtype.h"
#include "vnr/json.h"
#include "vnr/math.h"
#include "vnr/core/value_range_grid.h"
#include "vnr/nn/model_file.h"
#include "vnr/nn/network.h"
#include "vnr/train/residuals.h"

namespace vnr {

struct BrickedModel;  // train/bricks.h

// A network together with what it represents: the bridge between the in-memory Network and the
// model files.
struct Model {
  std::unique_ptr<Network> net;
  Int3 dims;
  DType source_dtype = DType::Float32;
  double lo = 0, hi = 1;
  Json training;  // summary written by `vnr train`
  std::optional<ValueRangeGrid> macrocells;  // value ranges built online while training (or imported)
  // Error-bound residuals at dims (train/residuals.h): decodes at dims apply them on the CPU reference.
  std::optional<Residuals> residuals;
  // Quantization steps of compact storage (nn/param_codec.h); empty = plain fp16. The network's
  // parameters are then already the dequantized values (quantize_params), so the file holds them exactly.
  std::vector<ParamSegment> param_segments;
  // A multi-brick model (a directory, train/bricks.h): net is then a copy of brick 0's network (config,
  // precision); queries, decodes, evaluation and rendering go through the bricks.
  std::shared_ptr<BrickedModel> bricks;
  // What a single network and a multi-brick model answer alike (bricks_model.cpp), so that callers need
  // not ask which it is: parameters (all bricks'), their fp16 bytes as stored, and whether a session can
  // train it (a multi-brick model is trained brick by brick: train_bricks).
  uint64_t n_params() const;
  uint64_t param_bytes() const { return n_params() * 2; }
  bool trainable() const { return bricks == nullptr; }
};

// A fresh model of `config` for a volume of dims voxels of source_dtype with value range [lo, hi] in
// original units, its parameters initialised from `seed` (tcnn's initialisation, Network::init_params).
Model create_model(const ModelConfig& config, Int3 dims, DType source_dtype, double lo, double hi, uint32_t seed = 1337);

// Writes .vnr, or instantvnr's BSON when the path ends in .bson or .json (instantvnr names its
// BSON files params.json).
void save_model(const std::string& path, const Model& m);
// The .vnr file save_model writes for a single-network model, and its size (without writing it).
ModelFile model_file(const Model& m);
uint64_t model_file_bytes(const Model& m);
// The file's description of m (config, dims, dtype, range, training summary, macro-cells) without the
// parameters, residuals or storage choices: save_model and the rate search fill those in.
ModelFile model_file_without_params(const Model& m);
Model load_model(const std::string& path);
bool is_instantvnr_path(const std::string& path);

// Whether the model file records the value range of the volume it was trained on: .vnr files do,
// instantvnr BSON files do not (load_model then gives [0, 1]). Reads only the file's first bytes.
bool model_file_has_value_range(const std::string& path);

}  // namespace vnr
