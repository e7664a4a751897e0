#pragma once
// Single-point evaluation of a Network, for the renderer's "in-shader" strategy (each ray queries the
// field one point at a time inside its own loop). Same semantics as Network::infer: the fp16 grid
// working copy (grid_half()), the same encoding (every grid type and interpolation; parameter-free
// encodings go through Network::encode_point), the bias-free MLP with its hidden and output
// activations. Only the MLP summation order differs (results agree to rounding); the grid features
// are bit-identical to Network::encode_point.
//
// Construction (once per frame / model) copies the MLP weights into a SIMD-friendly layout and
// resolves the Highway dispatch once into function pointers specialised on the features per level
// and the MLP panel width; eval() is then one indirect call, const, thread-safe and allocation-free
// (stack buffers sized by the config limits: 32 levels x 8 features, 1024 neurons, 3072-wide
// parameter-free encodings).
//
//   Encoding: the 8 corners of every level are computed at once with lanes = levels (index terms
//   shared between corners: two integer multiplies per level vector), the corner lines of the
//   levels whose table exceeds L2 are prefetched (L2 hint) so that all their misses overlap, then
//   each corner's F fp16 features are loaded, converted and accumulated (one FMA per corner, in
//   corner order as the reference). prefetch() issues the same prefetches for a later point.
//   MLP: weights transposed into panels of PW (16/32/64) outputs: for each input i the panel row
//   W[p*PW .. p*PW+PW, i] is contiguous and FMAs into PW/lanes accumulators with x[i] broadcast;
//   2-8 accumulator sets break the FMA latency chains. After a ReLU layer of more than 32 neurons,
//   the inputs that are exactly zero are compacted away (their products add exactly 0, so the
//   result is unchanged up to summation order; only when every weight is finite, as 0 * inf is NaN).
#include <cstdint>
#include <hwy/aligned_allocator.h>
#include "vnr/model_config.h"
#include "vnr/nn/grid_encoding.h"

namespace vnr {

class Network;

// Internal: everything the per-target kernels read. Plain data, filled by the constructor.
struct PointEvalData {
  static constexpr uint32_t kMaxWidth = 1024;  // NetworkConfig: n_neurons in 1..1024
  // ---- encoding ----
  const Network* net = nullptr;       // parameter-free encodings: Network::encode_point
  const uint16_t* table = nullptr;    // fp16 grid (net.grid_half())
  GridLayout grid;
  bool has_grid = false;
  uint32_t first_big = kMaxGridLevels;  // first level whose table exceeds 256 KiB (prefetched)
  // Level constants as lane arrays (lanes = levels; padded to kMaxGridLevels with harmless values).
  alignas(64) float lvl_scale[kMaxGridLevels];
  // Corner index = X ^ Y ^ Z (hashed) or X + Y + Z (dense) with Y = cy * m1, Z = cz * m2.
  alignas(64) uint32_t lvl_m1[kMaxGridLevels], lvl_m2[kMaxGridLevels];
  alignas(64) uint32_t lvl_n[kMaxGridLevels];       // n_l
  alignas(64) uint32_t lvl_mask[kMaxGridLevels];    // n_l - 1 for power-of-two n_l, else ~0
  alignas(64) uint32_t lvl_hashed[kMaxGridLevels];
  alignas(64) uint32_t lvl_offset[kMaxGridLevels];  // first entry of the level
  const uint16_t* lvl_ptr[kMaxGridLevels];          // the level's table
  uint8_t lvl_vec[kMaxGridLevels];    // 0: the level takes the scalar path (tiled levels with n_l < res^3)
  uint8_t lvl_big[kMaxGridLevels];    // the level's table exceeds 256 KiB (L2-sized): corner lines prefetched
  // ---- MLP ----
  uint32_t k0 = 0;         // inputs of W_0 that are used (first_cols)
  uint32_t in_pad = 0, enc_width = 0;
  float pad_value = 0;
  uint32_t width = 0, n_hidden = 0;
  uint32_t panel = 16, n_panels = 1, width_pad = 16;  // hidden outputs in n_panels panels of `panel`
  bool relu = true, skip_zeros = false;
  Activation out_act = Activation::None;
  const float* layer[34] = {};  // layer k: n_panels blocks of (K_k rows x panel), row i = input i
  const float* wout = nullptr;  // first output row, width_pad floats (zero-padded)
  // ---- bf16 MLP (Precision::BF16; see mlp_bf16.h for the pair layout) ----
  // layer k: n_panels blocks of (ceil(K_k / 2) pair rows x panel words), row j = inputs 2j, 2j + 1;
  // output row 0 as width_pad / 2 pair words. The bf16 eval encodes through `encode`.
  const uint32_t* layer_bf16[34] = {};
  const uint32_t* wout_bf16 = nullptr;
  void (*encode)(const PointEvalData&, float, float, float, float*) = nullptr;
};

// The per-target functions a PointEvaluator calls (filled by select_point_kernels).
struct PointEvalKernels {
  float (*eval)(const PointEvalData&, float, float, float) = nullptr;
  void (*encode)(const PointEvalData&, float, float, float, float*) = nullptr;
  float (*mlp)(const PointEvalData&, const float*) = nullptr;
  void (*prefetch)(const PointEvalData&, float, float, float) = nullptr;
  const char* target = "";
};
// The kernels for a grid of F features per level (F = 1, 2, 4, 8; 0: no grid), for the best SIMD target:
// what the network's Encoding::select_point_kernels calls with the F its factory fixed.
template <int F>
void select_point_kernels(const PointEvalData& d, PointEvalKernels* k);
#define VNR_SELECT_POINT_KERNELS_OF(F) \
  template <>                        \
  void select_point_kernels<F>(const PointEvalData&, PointEvalKernels*);
VNR_SELECT_POINT_KERNELS_OF(0)
VNR_GRID_FEATURE_COUNTS(VNR_SELECT_POINT_KERNELS_OF)
#undef VNR_SELECT_POINT_KERNELS_OF

class PointEvaluator {
public:
  // Keeps a reference to net (its fp16 grid and, for parameter-free encodings, encode_point): net
  // must outlive the evaluator; rebuild the evaluator after changing net's parameters.
  // skip_zero_activations: compact away the exact zeros after ReLU layers for widths > 32 (the
  // remaining products are the same; off only for measurements).
  explicit PointEvaluator(const Network& net, bool skip_zero_activations = true);
  PointEvaluator(PointEvaluator&&) = default;
  PointEvaluator& operator=(PointEvaluator&&) = default;

  // First network output (after the output activation) at u = (x, y, z), normally in [0, 1)^3.
  float eval(float x, float y, float z) const { return eval_(d_, x, y, z); }

  // Optional hint for a point that will be evaluated soon (e.g. the ray's next sample): starts the
  // cache misses of its large grid levels now, so that they overlap the current evaluation.
  // No effect on results; a no-op for parameter-free encodings or points outside the unit cube.
  void prefetch(float x, float y, float z) const { prefetch_(d_, x, y, z); }

  // The two halves of eval(), for tests and profiling. encode writes the padded encoding (in_pad()
  // floats, pad_value past the encoding width); mlp reads one and returns what eval() would.
  void encode(float x, float y, float z, float* enc) const { encode_(d_, x, y, z, enc); }
  float mlp(const float* enc) const { return mlp_(d_, enc); }

  uint32_t in_pad() const { return d_.in_pad; }
  // BF16 when built from a network whose inference_precision() is BF16 and whose width exceeds 16
  // (the MLP then runs on bf16 pairs with vdpbf16ps, as Network::infer does, without zero
  // compaction); else FP32 (16-wide networks: faster in fp32 here, see point_eval_bf16.cpp).
  Precision precision() const { return precision_; }
  bool skips_zeros() const { return d_.skip_zeros; }
  const char* simd_target() const { return target_; }  // the Highway target chosen at construction

  using EvalFn = decltype(PointEvalKernels::eval);
  using EncodeFn = decltype(PointEvalKernels::encode);
  using MlpFn = decltype(PointEvalKernels::mlp);
  using PrefetchFn = decltype(PointEvalKernels::prefetch);

private:
  PointEvalData d_;
  hwy::AlignedFreeUniquePtr<float[]> weights_;
  hwy::AlignedFreeUniquePtr<uint32_t[]> weights_bf16_;
  Precision precision_ = Precision::FP32;
  EvalFn eval_ = nullptr;
  EncodeFn encode_ = nullptr;
  MlpFn mlp_ = nullptr;
  PrefetchFn prefetch_ = nullptr;
  const char* target_ = "";
};

namespace point_eval {
// The bf16 MLP and eval for a panel width of 32 or 64 (point_eval_bf16.cpp; AVX512-BF16 only);
// nullptr otherwise.
PointEvaluator::MlpFn bf16_mlp(uint32_t panel);
PointEvaluator::EvalFn bf16_eval(uint32_t panel);
}  // namespace point_eval

}  // namespace vnr
