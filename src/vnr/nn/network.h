#pragma once
// The composite model "network with input encoding" (docs/semantics.md A.5): an encoding object
// (nn/encoding.h: grid or parameter-free) followed by a bias-free MLP; flat fp32 master parameters in
// tcnn order (MLP matrices W_0..W_H first, then the encoding's parameters: the grid table).
// Implementation by concern: network.cpp (parameters, init, encoding), network_mlp.cpp (fp32 MLP),
// network_bf16.cpp (bf16 inference and training), network_infer.cpp (threaded inference),
// network_reference.cpp (plain-loop reference).
#include <atomic>
#include <memory>
#include <cstdint>
#include <type_traits>
#include <vector>
#include "vnr/json.h"
#include "vnr/memory.h"
#include "vnr/core/parallel.h"
#include "vnr/core/rng.h"
#include "vnr/model_config.h"
#include "vnr/nn/encoding.h"
#include "vnr/nn/grid_encoding.h"
#include "vnr/nn/mlp_layout.h"

namespace vnr {

class Adam;

// tiny-cuda-nn's GPU uniform fill (docs/semantics.md A.2.10): element idx = i + T*j takes stream number
// 4*i + j counted from rng's state, T = 128 * ceil(ceil(n/4)/128); afterwards rng is advanced by n.
void tcnn_uniform_fill(Pcg32& rng, float* out, uint64_t n, float lower, float upper);

// Samples are processed in chunks of kChunk, whose MLP activations stay in L2 beside the grid tables,
// for every width (training draws its samples per (step, chunk), so the GPU trainer uses the same
// chunks). Training batches are multiples of kChunk.
constexpr int kChunk = 256;

class Network {
  big_vector<float> params_;  // the fp32 master copy (first, as the public array was: the same layout)

public:
  explicit Network(const ModelConfig& config, uint32_t n_output_dims = 1);
  // The same from tiny-cuda-nn JSON (parsed by ModelConfig::from_json): model files and tests.
  explicit Network(const Json& config, uint32_t n_output_dims = 1)
      : Network(ModelConfig::from_json(config), n_output_dims) {}

  const ModelConfig& config() const { return cfg_; }
  const Json& config_json() const { return cfg_json_; }
  const Encoding& encoding() const { return *enc_; }
  bool has_grid() const { return enc_->grid() != nullptr; }
  const GridLayout& grid() const { return grid_; }
  const MlpLayout& mlp() const { return mlp_; }
  uint64_t n_params() const { return mlp_.n_params + grid_params(); }
  uint64_t grid_params() const { return enc_->n_params(); }
  double flops_forward_per_sample() const;  // 2 * MACs of the unpadded-output MLP

  // The parameters: an fp32 master copy (size n_params(), the MLP's then the grid's) and the fp16
  // working copy of the grid that every forward pass reads (tcnn's model: fp32 master for the optimizer,
  // half for forward/backward/inference). The network keeps the two in step: every write goes through
  // edit_params, set_params, set_params_half or adam_step.
  const big_vector<float>& params() const { return params_; }
  const float* grid_table() const { return params_.data() + mlp_.n_params; }
  const uint16_t* grid_half() const { return grid_half_.data(); }
  // fn(float* params, size_t n) writes the master copy; the half copy follows it afterwards.
  template <typename Fn>
  void edit_params(Fn&& fn) {
    fn(params_.data(), params_.size());
    sync_half_table();
  }
  void set_params(const float* values, size_t n);  // n == n_params(), else one error
  // One step of `adam` with these gradients (n_params() of them): it updates both copies together.
  void adam_step(Adam& adam, float* grads);

  // tiny-cuda-nn initialisation (docs/semantics.md A.4.1, A.2.10, A.8): Xavier-uniform MLP matrices then the
  // grid fill U[-1e-4, 1e-4), all from pcg32 seeded with seed_seq{seed}.
  void init_params(uint32_t seed);
  std::vector<uint16_t> params_half() const;
  void set_params_half(const std::vector<uint16_t>& h);

  // ---- chunk kernels (single-threaded; callers parallelise over chunks) ----
  // X0 (in_pad x n, feature-major) = padded encoding of the n points (x[i], y[i], z[i]).
  void encode(const float* x, const float* y, const float* z, int n, float* X0) const;
  // acts: n_hidden blocks of width x n (post-activation); out: n_out x n (post-activation),
  // out_pre: pre-activation of the output layer (may alias out when the output activation is None).
  void mlp_forward(const float* X0, int n, float* acts, float* out_pre, float* out) const;
  // bf16 inference forward (Precision::BF16): wp = bf16_weights() (every matrix as bf16 pairs, see
  // mlp_bf16.h), scratch mlp_bf16_scratch(n) words; out: first output row after the output activation.
  std::vector<uint32_t> bf16_weights() const;
  size_t mlp_bf16_scratch(int n) const { return (size_t(mlp_.first_cols + 1) / 2 + mlp_.width + mlp_.n_out) * n; }
  void mlp_forward_bf16(const float* X0, int n, const uint32_t* wp, uint32_t* scratch, float* out) const;
  // Given dL/d(out_pre) (n_out x n): accumulates dW (n_mlp params) and writes dL/dX0 (in_pad x n)
  // when dX0 != nullptr. scratch: 2 * width * n floats.
  void mlp_backward(const float* X0, const float* acts, const float* d_out_pre, int n, float* dW, float* dX0,
                    float* scratch) const;
  // ---- bf16 training (TrainOptions::precision BF16; kernels in mlp_bf16_train.h) ----
  // ReLU MLPs of width 16, 32, 64 or 128 (every FullyFusedMLP) with at most 128 inputs and outputs,
  // on CPUs with AVX512-BF16.
  bool bf16_training_supported() const;
  // The matrices as bf16 pairs in the two layouts the kernels read: wt (pairs over columns, lanes
  // over rows: forward) and wp (pairs over rows, lanes over columns: data gradient). The weights
  // change every step: the trainer converts them once per step.
  struct Bf16TrainWeights {
    std::vector<uint32_t> data;
    uint64_t wt[34], wp[34];  // offsets into data, per matrix
  };
  Bf16TrainWeights bf16_train_weights() const;
  size_t mlp_train_bf16_scratch(int n) const;  // uint32 words for one chunk of n samples
  // mlp_forward's out_pre and out from bf16 operands; the activations stay (bf16, sample-major) in
  // scratch for mlp_backward_train_bf16 of the same chunk. n a multiple of 32.
  void mlp_forward_train_bf16(const float* X0, int n, const Bf16TrainWeights& w, uint32_t* scratch, float* out_pre,
                              float* out) const;
  // mlp_backward's dW (accumulated) and dX0 (when not null) from bf16 operands.
  void mlp_backward_train_bf16(const float* d_out_pre, int n, const Bf16TrainWeights& w, uint32_t* scratch,
                               float* dW, float* dX0) const;
  // Grid parameter gradient of one level for samples [0, n): grad += dL/dtheta, reading the
  // encoding gradient from dEnc in the chunked layout (chunk c at c * in_pad * chunk, row stride chunk).
  void grid_backward_level(uint32_t level, const float* x, const float* y, const float* z, int64_t n,
                           const float* dEnc, int chunk, float* grad) const;
  size_t acts_floats(int n) const { return size_t(mlp_.n_hidden) * mlp_.width * n; }

  // Precision of infer/infer_fn and of PointEvaluators built afterwards (default FP32). BF16 applies
  // to ReLU MLPs of even width; others stay fp32 (inference_precision() then says FP32).
  void set_inference_precision(Precision p);
  Precision inference_precision() const { return precision_; }

  // ---- batched queries (parallel inside) ----
  // out[i] = first network output at point i; coords interleaved xyz.
  void infer(const float* coords, int64_t n, float* out) const;
  // Same, with points produced on the fly: coord(i, &x, &y, &z) per point, or coord(first, count, x, y, z)
  // filling a whole chunk of SoA arrays.
  template <typename CoordFn>
  void infer_fn(int64_t n, CoordFn&& coord, float* out) const;

  // Reference evaluation of one point, plain loops, for tests.
  float eval_reference(float x, float y, float z) const;
  // Encoding of one point (enc_width values, unpadded) and its Jacobian d enc_j / d x_d (enc_width x 3).
  void encode_point(const float xyz[3], float* out) const;
  void encode_point_input_grad(const float xyz[3], float* jac) const;

private:
  void sync_half_table();
  float* grid_table_mut() { return params_.data() + mlp_.n_params; }
  void infer_chunk(const float* x, const float* y, const float* z, int n, float* out, float* ws) const;
  void infer_chunk_bf16(const float* x, const float* y, const float* z, int n, float* out, float* ws,
                        const uint32_t* wp) const;
  size_t infer_workspace_floats() const;
  // Inference of n samples takes the in-register 16-wide kernels (fp32 mlp_forward_16 or its bf16 twin).
  bool fused_16(int n) const;
  // This thread's inference scratch, grown as needed and kept, so that the many small calls of the
  // renderers do not each map and fault in a few hundred KiB.
  static float* thread_workspace(size_t floats);

  ModelConfig cfg_;
  Json cfg_json_;
  std::shared_ptr<const Encoding> enc_;  // immutable, shared by copies of the Network
  big_vector<uint16_t> grid_half_;
  Precision precision_ = Precision::FP32;
  GridLayout grid_;
  MlpLayout mlp_;
};

template <typename CoordFn>
void Network::infer_fn(int64_t n, CoordFn&& coord, float* out) const {
  const int64_t C = kChunk;
  const int64_t n_chunks = (n + C - 1) / C;
  // Converted per call (cheap next to a batch): the parameters may change between calls (online training).
  const std::vector<uint32_t> wp = precision_ == Precision::BF16 ? bf16_weights() : std::vector<uint32_t>();
  // Chunks are claimed as threads get free (a chunk's outputs do not depend on its thread): a static
  // split leaves one thread waiting whenever another core is slowed.
  std::atomic<int64_t> next_chunk{0};
  parallel_threads([&](int, int) {
    float* ws = thread_workspace(infer_workspace_floats() + 4 * C);
    float* xs = ws + infer_workspace_floats();
    float *ys = xs + C, *zs = ys + C, *o = zs + C;
    for_each_claimed(next_chunk, n_chunks, [&](int64_t c) {
      int64_t b = c * C, m = n - b < C ? n - b : C;
      int64_t mp = (m + 15) / 16 * 16;  // kernels work on multiples of 16 samples
      if constexpr (std::is_invocable_v<CoordFn&, int64_t, int64_t, float*, float*, float*>) {
        coord(b, m, xs, ys, zs);
        for (int64_t i = m; i < mp; ++i) xs[i] = xs[m - 1], ys[i] = ys[m - 1], zs[i] = zs[m - 1];
      } else {
        for (int64_t i = 0; i < mp; ++i) coord(b + (i < m ? i : m - 1), &xs[i], &ys[i], &zs[i]);
      }
      float* dst = m == mp ? out + b : o;  // the tail's padded outputs go to scratch
      if (wp.empty()) infer_chunk(xs, ys, zs, int(mp), dst, ws);
      else infer_chunk_bf16(xs, ys, zs, int(mp), dst, ws, wp.data());
      if (dst == o)
        for (int64_t i = 0; i < m; ++i) out[b + i] = o[i];
    });
  });
}

}  // namespace vnr
