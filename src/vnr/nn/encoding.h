#pragma once
// Input encodings as objects (docs/semantics.md A.2, A.3): one implementation per tiny-cuda-nn
// otype family, each in its own file under nn/encodings/, created from the config's encoding object
// by a registry keyed by otype.
//
// Adding an encoding touches ONE file: nn/encodings/<name>.cpp defines the class, its otype names,
// parsing of its own keys (EncodingConfig fields or EncodingConfig::options), its describe-back JSON,
// and ends with VNR_ENCODING_REGISTRAR(<name>) { ... }. CMake lists every file of nn/encodings/ at
// configure time (generated encoding_list.inc), so the registry calls each registrar without a
// hand-kept list and the linker keeps every encoding.
//
// The Network calls an encoding once per chunk (forward/backward over n samples): no virtual call per
// sample. The parameters are held by the Network (fp16 working copy for forward, fp32 gradients).
#include <cstdint>
#include <memory>
#include <string>
#include <vector>
#include "vnr/json.h"
#include "vnr/model_config.h"
#include "vnr/nn/grid_encoding.h"

namespace vnr {

struct PointEvalData;     // nn/point_eval.h
struct PointEvalKernels;  // nn/point_eval.h

class Encoding {
public:
  virtual ~Encoding() = default;
  // Output features per point (before the MLP's padding).
  virtual uint32_t output_width() const = 0;
  // The MLP's padded input width is a multiple of this (grids: features per level; OneBlob: bins).
  virtual uint32_t min_alignment() const { return 1; }
  // Value of the padding inputs: 1 acts as a bias input for parameter-free encodings, grids pad with 0.
  virtual float pad_value() const { return 1.0f; }
  // Trainable parameters (stored after the MLP's in the flat parameter vector).
  virtual uint64_t n_params() const { return 0; }
  // The grid's layout for the backends that run it with their own kernels (GPU, point evaluator).
  virtual const GridLayout* grid() const { return nullptr; }

  // Rows [0, output_width()) of X0 (feature-major, row stride n) for the n points (x[i], y[i], z[i]);
  // params: this encoding's fp16 parameters (nullptr when it has none).
  virtual void forward(const float* x, const float* y, const float* z, int n, const uint16_t* params,
                       float* X0) const = 0;
  // Parameter gradient in independent parts (grid levels) that callers give to one thread each:
  // grad += dL/dtheta of part `part` for samples [0, n), dEnc chunked (chunk c at c * in_pad * chunk).
  virtual uint32_t n_backward_parts() const { return 0; }
  virtual void backward(uint32_t part, const float* x, const float* y, const float* z, int64_t n, const float* dEnc,
                        uint32_t in_pad, int chunk, float* grad) const {
    (void)part, (void)x, (void)y, (void)z, (void)n, (void)dEnc, (void)in_pad, (void)chunk, (void)grad;
  }
  // One point: out[output_width()], bit-identical to forward()'s column; jac[output_width() x 3] =
  // d out_j / d x_d (every entry written).
  virtual void encode_point(const float xyz[3], const uint16_t* params, float* out) const = 0;
  virtual void encode_point_input_grad(const float xyz[3], const uint16_t* params, float* jac) const = 0;
  // The CPU point evaluator's kernels for this encoding: grids give those of their features per level,
  // fixed when the factory made them; the others the grid-free kernels (select_point_kernels<0>).
  virtual void select_point_kernels(const PointEvalData& d, PointEvalKernels* k) const;
  // The encoding object of tiny-cuda-nn's JSON, every key explicit (the bytes of model files).
  virtual Json to_json() const = 0;
};

// One registered otype family.
struct EncodingSpec {
  std::string family;                // EncodingConfig::family of configs it parses, e.g. "Grid"
  std::vector<std::string> otypes;   // accepted otype names (case-insensitive), as listed in errors
  int list_order = 0;                // position of otypes in the "allowed:" list of errors
  // Fills e from the encoding object j (otype already matched, given in lower case).
  void (*parse)(const std::string& otype_lower, const Json& j, EncodingConfig& e) = nullptr;
  std::unique_ptr<Encoding> (*create)(const EncodingConfig& e) = nullptr;
};

class EncodingRegistry {
public:
  void add(EncodingSpec spec);
  const EncodingSpec* find_otype(const std::string& otype) const;  // nullptr when unknown
  const EncodingSpec* find_family(const std::string& family) const;
  std::string allowed_otypes() const;  // "HashGrid, DenseGrid, ..." in list order
private:
  std::vector<EncodingSpec> specs_;
};

// Every encoding of nn/encodings/, registered on first use.
const EncodingRegistry& encoding_registry();

// The typed encoding config of the config's "encoding" object; an unknown otype is an error listing
// the registered ones.
EncodingConfig parse_encoding_config(const Json& j);
// The encoding object of e (otype-family dispatch through the registry).
std::unique_ptr<Encoding> make_encoding(const EncodingConfig& e);

}  // namespace vnr

// Defines the registrar of the encoding file nn/encodings/<stem>.cpp, called by encoding_registry().
#define VNR_ENCODING_REGISTRAR(stem)                              \
  namespace vnr {                                                 \
  void register_encoding_##stem(EncodingRegistry& registry);      \
  }                                                               \
  void vnr::register_encoding_##stem(vnr::EncodingRegistry& registry)
