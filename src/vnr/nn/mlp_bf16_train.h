#pragma once
// bf16 kernels of the MLP training step (AVX512-BF16 `vdpbf16ps`): weights, the encoded input,
// activations and gradients rounded to bf16, every sum in fp32 (the master weights, Adam and the
// grid stay fp32). Rounding to bf16 keeps training quality (docs/benchmarks.md "bf16 training").
//
// Training works sample-major ("SM": sample s's features contiguous) so that all three products
// of a layer - forward, data gradient and weight gradient - are one kind of kernel, with no
// horizontal sums: a *pair GEMM* broadcasts one bf16 pair of P per row and multiplies it into V
// vectors of 16 lanes of Q:
//
//   C_i[l] = sum_{k < kp} lo(P_ik) lo(Q_kl) + hi(P_ik) hi(Q_kl),  P_ik = P[i*si + k*sk],
//            Q_kl = Q[k*ldq + l],  l < 16 V.
//
// - forward:      i = sample, k = input feature pair, l = output neuron (Q = W^T in pairs over columns);
// - data grad:    i = sample, k = output neuron pair, l = input feature (Q = W in pairs over rows);
// - weight grad:  i = output neuron, k = sample pair, l = input feature (P, Q = "sample pairs":
//                 S[j][c] = (A[2j][c], A[2j+1][c])), accumulated over a chunk in registers and
//                 added to dW once per chunk.
#include <cstdint>

namespace vnr::kernels {

// What a pair GEMM does with row i's 16 V results (dst row i at dst + i * ld, in dst's element type).
enum class PairGemmOut {
  ReluBf16,  // uint16 bf16(max(C, 0))
  MaskBf16,  // uint16 bf16(C) where mask row i (bf16 words) is > 0, else 0 (ReLU's derivative)
  F32,       // float C
  AddF32,    // float += C for lanes < valid
  Column,    // float lanes l < valid to dst[l * ld + i] (an output layer's rows, feature-major)
};

struct PairGemm {
  const uint32_t* P = nullptr;
  int64_t si = 0, sk = 0;
  int kp = 0;
  const uint32_t* Q = nullptr;
  int ldq = 0;
  int V = 1;  // 1, 2, 4 or 8
  int M = 0;  // rows
  PairGemmOut out = PairGemmOut::F32;
  void* dst = nullptr;
  int64_t ld = 0;
  const uint16_t* mask = nullptr;  // MaskBf16
  int64_t mask_ld = 0;
  int valid = 0;  // AddF32, Column
};
void pair_gemm(const PairGemm& g);

// X (K x n floats, feature-major, row stride n) -> A: n rows of ceil(K/2) bf16 pairs (row stride
// lda pairs); n a multiple of 16.
void feature_major_to_sm_pairs(const float* X, int K, int n, uint32_t* A, int lda);
// The first K columns of D (n rows, row stride ldd >= round16(K) floats) -> X (K x n, row stride
// ldx); n a multiple of 16.
void sm_to_feature_major(const float* D, int ldd, int K, int n, float* X, int ldx);
// S[j * lds + c] = (A[2j][c], A[2j+1][c]) for c < lds, 0 past K: A is n rows of bf16 words (row
// stride lda words), lds a multiple of 16 >= K, n even.
void sample_pairs(const uint16_t* A, int lda, int K, int n, uint32_t* S, int lds);

namespace ref {
// The same operands, products summed in double, then the same epilogue.
void pair_gemm(const PairGemm& g);
}  // namespace ref

}  // namespace vnr::kernels
