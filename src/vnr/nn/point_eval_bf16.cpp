// The in-shader evaluator's bf16 MLP (PointEvaluator with Precision::BF16): SIMD across a panel of
// output neurons as in the fp32 version, but each step takes a pair of inputs, so one vdpbf16ps
// does two multiply-adds per output (AVX512-BF16, x86 only; see mlp_bf16.h for the pair layout).
// Panels of 32 and 64 outputs only: for 16-wide networks the per-layer pair conversion costs more
// than the halved dot products save, so those stay fp32.
// The operands are the batched bf16 path's (Network::mlp_forward_bf16): the same bf16 weights, the
// encoding and every hidden activation rounded to bf16; only the fp32 summation order differs.
#include "vnr/nn/point_eval.h"

#include "vnr/model_config.h"
#include "vnr/nn/grid_encoding.h"
#include "vnr/nn/loss.h"

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define VNR_BF16_TARGET __attribute__((target("avx512f,avx512bw,avx512vl,avx512dq,avx512bf16")))

namespace vnr::point_eval {
namespace {

constexpr uint32_t kEncMax = kMaxParameterFreeWidth > kMaxGridLevels * 8 ? kMaxParameterFreeWidth : kMaxGridLevels * 8;
constexpr uint32_t kWordsMax = PointEvalData::kMaxWidth / 2 + 32;  // width_pad / 2, padded

// One panel of PW = 16 NV outputs: out (PW / 2 pair words) = pairs(ReLU(sum_j W[row j] . x[j])) over
// n input pairs. (No compaction of zero inputs as in fp32: at pair granularity few pairs are zero,
// so skipping them costs more in the data-dependent loop than it saves.)
template <int NV>
VNR_BF16_TARGET inline void Panel(const uint32_t* __restrict W, const uint32_t* __restrict x, uint32_t n, bool relu,
                                  uint32_t* __restrict out) {
  constexpr int PW = 16 * NV;
  // Independent chains to cover the dot-product latency; a 16-wide layer has only 4-8 pairs, so it
  // keeps 4 chains rather than 8 (fewer partial sums to add up).
  constexpr int S = NV >= 4 ? 8 / NV : 4;
  __m512 acc[S][NV];
  for (int s = 0; s < S; ++s)
    for (int v = 0; v < NV; ++v) acc[s][v] = _mm512_setzero_ps();
  uint32_t j = 0;
  for (; j + S <= n; j += S)
    for (int s = 0; s < S; ++s) {
      const __m512bh xv = (__m512bh)_mm512_set1_epi32(int(x[j + s]));
      const uint32_t* row = W + size_t(j + s) * PW;
      for (int v = 0; v < NV; ++v)
        acc[s][v] = _mm512_dpbf16_ps(acc[s][v], (__m512bh)_mm512_load_si512(row + 16 * v), xv);
    }
  for (; j < n; ++j) {
    const __m512bh xv = (__m512bh)_mm512_set1_epi32(int(x[j]));
    const uint32_t* row = W + size_t(j) * PW;
    for (int v = 0; v < NV; ++v) acc[0][v] = _mm512_dpbf16_ps(acc[0][v], (__m512bh)_mm512_load_si512(row + 16 * v), xv);
  }
  for (int w = S / 2; w >= 1; w /= 2)  // pairwise: log2(S) dependent adds
    for (int s = 0; s < w; ++s)
      for (int v = 0; v < NV; ++v) acc[s][v] = _mm512_add_ps(acc[s][v], acc[s + w][v]);
  for (int v = 0; v < NV; ++v) {
    // maskz form: GCC 12 warns falsely about _mm512_max_ps's undefined pass-through
    const __m512 y = relu ? _mm512_maskz_max_ps(0xffff, acc[0][v], _mm512_setzero_ps()) : acc[0][v];
    // 16 outputs in order = 8 pair words (outputs 2i, 2i + 1)
    _mm256_store_si256(reinterpret_cast<__m256i*>(out + 8 * v), (__m256i)_mm512_cvtneps_pbh(y));
  }
}

// Rounds n floats to bf16 in order: n / 2 pair words (n even). Reads whole 16-float blocks (masked)
// and writes whole 8-word blocks (masked stores are slow on Zen 4): out needs n / 2 + 8 words.
VNR_BF16_TARGET inline void ToPairs(const float* x, uint32_t n, uint32_t* out) {
  for (uint32_t i = 0; i < n; i += 16) {
    const __mmask16 m = n - i >= 16 ? __mmask16(0xffff) : __mmask16((1u << (n - i)) - 1);
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(out + i / 2),
                        (__m256i)_mm512_cvtneps_pbh(_mm512_maskz_loadu_ps(m, x + i)));
  }
}

template <int PW>
VNR_BF16_TARGET float Mlp(const PointEvalData& d, const float* enc) {
  constexpr int NV = PW / 16;
  alignas(64) uint32_t in0[kEncMax / 2 + 16];
  alignas(64) uint32_t hbuf[2][kWordsMax];
  const uint32_t k0 = d.k0 + (d.k0 & 1);  // an odd k0's last pair meets a zero weight
  ToPairs(enc, k0, in0);
  const uint32_t* in = in0;
  uint32_t kp = k0 / 2;
  const uint32_t half = PW / 2;  // pair words per panel of outputs
  for (uint32_t k = 0; k < d.n_hidden; ++k) {
    uint32_t* h = hbuf[k & 1];
    const uint32_t* W = d.layer_bf16[k];
    const size_t panel_words = size_t(kp) * PW;
    for (uint32_t p = 0; p < d.n_panels; ++p) Panel<NV>(W + p * panel_words, in, kp, d.relu, h + p * half);
    in = h;
    kp = d.width / 2;  // the next matrix's pair rows (even widths only)
  }
  // Output row 0: pair words of the last hidden layer . the output weights (zero-padded). 256-bit
  // loads, as the panels stored them (a wider load would miss store-to-load forwarding).
  __m256 acc = _mm256_setzero_ps();
  for (uint32_t j = 0; j < kp; j += 8) {
    const __mmask8 m = kp - j >= 8 ? __mmask8(0xff) : __mmask8((1u << (kp - j)) - 1);
    acc = _mm256_dpbf16_ps(acc, (__m256bh)_mm256_maskz_loadu_epi32(m, d.wout_bf16 + j),
                           (__m256bh)_mm256_maskz_loadu_epi32(m, in + j));
  }
  __m128 s4 = _mm_add_ps(_mm256_castps256_ps128(acc), _mm256_extractf128_ps(acc, 1));
  s4 = _mm_add_ps(s4, _mm_movehl_ps(s4, s4));
  const float y = _mm_cvtss_f32(_mm_add_ss(s4, _mm_movehdup_ps(s4)));
  return d.out_act == Activation::None ? y : activate(d.out_act, y);
}

template <int PW>
VNR_BF16_TARGET float Eval(const PointEvalData& d, float x, float y, float z) {
  alignas(64) float enc[kEncMax + 16];
  d.encode(d, x, y, z, enc);
  return Mlp<PW>(d, enc);
}

}  // namespace

PointEvaluator::MlpFn bf16_mlp(uint32_t panel) {
  switch (panel) {
    case 32: return &Mlp<32>;
    case 64: return &Mlp<64>;
    default: return nullptr;
  }
}

PointEvaluator::EvalFn bf16_eval(uint32_t panel) {
  switch (panel) {
    case 32: return &Eval<32>;
    case 64: return &Eval<64>;
    default: return nullptr;
  }
}

}  // namespace vnr::point_eval

#else

namespace vnr::point_eval {
PointEvaluator::MlpFn bf16_mlp(uint32_t) { return nullptr; }
PointEvaluator::EvalFn bf16_eval(uint32_t) { return nullptr; }
}  // namespace vnr::point_eval

#endif
