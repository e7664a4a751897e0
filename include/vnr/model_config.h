#pragma once
// The model configuration (ModelConfig): public, self-contained; nn/ builds networks from it.
#include <cstdint>
#include <string>
#include "vnr/json.h"

namespace vnr {

// A model configuration in tiny-cuda-nn's JSON vocabulary (docs/semantics.md A.1-A.7), parsed into plain
// structs. Unknown keys are ignored (as tcnn does); unsupported values are errors that list the
// accepted ones.

// The built-in encoding families (nn/encodings/); an encoding added later has type Other and is
// known by EncodingConfig::family.
enum class EncodingType { Grid, Frequency, OneBlob, Identity, Other };
enum class GridType { Hash, Dense, Tiled };
enum class Interpolation { Nearest, Linear, Smoothstep };
enum class Activation { None, ReLU, Exponential, Sine, Sigmoid, Squareplus, Softplus };
enum class LossType { L1, L2, RelativeL2, RelativeL1 };

// Arithmetic of inference (batched queries and the in-shader point evaluator; training is always
// fp32). BF16: weights and activations rounded to bf16, products summed in fp32, on CPUs with
// AVX512-BF16 (twice the fp32 FMA rate); tiny-cuda-nn infers in fp16, whose rounding is of the same
// order.
enum class Precision { FP32, BF16 };
// "fp32", "bf16", or "auto" (bf16 where the CPU has AVX512-BF16, else fp32); anything else is an
// error listing them. "bf16" on a CPU without AVX512-BF16 is an error too (no slow emulation).
Precision parse_precision(const std::string& name);
const char* precision_name(Precision p);

// Bounds of the parameter-free encodings (their per-point outputs live in fixed-size stack buffers).
constexpr uint32_t kMaxFrequencies = 32, kMaxOneBlobBins = 1024;
constexpr uint32_t kMaxParameterFreeWidth = 3 * kMaxOneBlobBins;  // >= 3 * 2 * kMaxFrequencies

// Parsed by the encoding registry (nn/encoding.h): each family's file reads its own keys.
struct EncodingConfig {
  EncodingType type = EncodingType::Grid;
  std::string family = "Grid";  // the registered family that parsed it (EncodingSpec::family)
  // Grid
  GridType grid_type = GridType::Hash;
  uint32_t n_levels = 16, n_features_per_level = 2, log2_hashmap_size = 19, base_resolution = 16;
  float per_level_scale = 2.0f;
  Interpolation interpolation = Interpolation::Linear;
  // Frequency / OneBlob / Identity
  uint32_t n_frequencies = 12;
  uint32_t n_bins = 16;
  float scale = 1.0f, offset = 0.0f;
  // Keys of encodings whose parameters have no typed field here (kept by their parser).
  Json options;
};

struct NetworkConfig {
  bool fully_fused = true;  // FullyFusedMLP (widths 16/32/64/128, align 16) or CutlassMLP (any, align 8)
  uint32_t n_neurons = 128, n_hidden_layers = 5;
  Activation activation = Activation::ReLU, output_activation = Activation::None;
};

struct AdamConfig {
  float learning_rate = 1e-3f, beta1 = 0.9f, beta2 = 0.999f, epsilon = 1e-8f, l2_reg = 1e-8f;
  float relative_decay = 0, absolute_decay = 0;
  bool adabound = false;
  float non_matrix_learning_rate_factor = 1.0f;
  bool optimize_matrix_params = true, optimize_non_matrix_params = true;
};

struct DecayConfig {
  bool enabled = false;  // ExponentialDecay wrapper present
  float decay_base = 0.1f;
  uint32_t decay_start = 10000, decay_interval = 10000, decay_end = 10000000;
};

struct ModelConfig {
  EncodingConfig encoding;
  NetworkConfig network;
  LossType loss = LossType::RelativeL2;
  AdamConfig adam;
  DecayConfig decay;

  static ModelConfig from_json(const Json& j);  // the four-object tcnn config (or {"params": {...}})
  Json to_json() const;                         // the same vocabulary back, all keys explicit
};

// Built-in configurations: "paper" (the paper's fixed config, appendix), "small" (4 levels x 2
// features, 2^16 table, base 4, 16 x 2 MLP) and "tiny" (for tests).
Json preset_config(const std::string& name);
bool is_preset(const std::string& name);
const char* preset_names();  // "auto, paper, small"

// The typed config of a preset name or a JSON file path: parsed once here; everything downstream
// (--target-ratio sizing, learning-rate scaling, Network) works on the ModelConfig.
ModelConfig load_config(const std::string& preset_or_path);

const char* activation_name(Activation a);
const char* loss_name(LossType l);

}  // namespace vnr
