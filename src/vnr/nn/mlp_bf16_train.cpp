// bf16 training kernels: see mlp_bf16_train.h. x86 AVX512-BF16 only (as mlp_bf16.cpp), chosen at
// run time by the caller (bf16_supported()).
#include "vnr/nn/mlp_bf16_train.h"

#include "vnr/error.h"
#include "vnr/nn/bf16_simd.h"  // VNR_BF16_TARGET, mlp_bf16.h's conversions, pack_pairs

namespace vnr::kernels {

using bf16_detail::hi_of;
using bf16_detail::lo_of;

namespace {
void check(const PairGemm& g) {
  if (g.V != 1 && g.V != 2 && g.V != 4 && g.V != 8) fail("pair_gemm: V must be 1, 2, 4 or 8, got {}", g.V);
  if (g.M < 0 || g.kp < 0) fail("pair_gemm: negative size");
}
}  // namespace

namespace ref {
void pair_gemm(const PairGemm& g) {
  check(g);
  const int L = 16 * g.V;
  for (int i = 0; i < g.M; ++i)
    for (int l = 0; l < L; ++l) {
      double acc = 0;
      for (int k = 0; k < g.kp; ++k) {
        const uint32_t p = g.P[i * g.si + k * g.sk], q = g.Q[int64_t(k) * g.ldq + l];
        acc += double(lo_of(p)) * lo_of(q) + double(hi_of(p)) * hi_of(q);
      }
      const float c = float(acc);
      switch (g.out) {
        case PairGemmOut::ReluBf16: static_cast<uint16_t*>(g.dst)[i * g.ld + l] = to_bf16(c > 0 ? c : 0.0f); break;
        case PairGemmOut::MaskBf16:
          static_cast<uint16_t*>(g.dst)[i * g.ld + l] = int16_t(g.mask[i * g.mask_ld + l]) > 0 ? to_bf16(c) : 0;
          break;
        case PairGemmOut::F32: static_cast<float*>(g.dst)[i * g.ld + l] = c; break;
        case PairGemmOut::AddF32:
          if (l < g.valid) static_cast<float*>(g.dst)[i * g.ld + l] += c;
          break;
        case PairGemmOut::Column:
          if (l < g.valid) static_cast<float*>(g.dst)[l * g.ld + i] = c;
          break;
      }
    }
}
}  // namespace ref

#if VNR_HAVE_BF16_KERNELS

namespace {

VNR_BF16_TARGET inline void store_bf16(uint16_t* p, __m512 v) {
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(p), (__m256i)_mm512_cvtneps_pbh(v));
}

// Epilogues: called once per row with its V accumulators.
// shifted(l): the same epilogue for lanes l, l + 1, ... of each row (V = 8 runs as two halves).
struct ReluBf16 {
  uint16_t* dst;
  int64_t ld;
  ReluBf16 shifted(int l) const { return {dst + l, ld}; }
  template <int V>
  VNR_BF16_TARGET void operator()(int i, const __m512 (&acc)[V]) const {
    // max(x, 0) returns its second operand for NaN: ReLU maps NaN to 0 as the fp32 kernels do.
    for (int v = 0; v < V; ++v) store_bf16(dst + i * ld + 16 * v, _mm512_maskz_max_ps(0xffff, acc[v], _mm512_setzero_ps()));
  }
};
struct MaskBf16 {
  uint16_t* dst;
  int64_t ld;
  const uint16_t* mask;
  int64_t mask_ld;
  MaskBf16 shifted(int l) const { return {dst + l, ld, mask + l, mask_ld}; }
  template <int V>
  VNR_BF16_TARGET void operator()(int i, const __m512 (&acc)[V]) const {
    for (int v = 0; v < V; ++v) {
      const __m256i a = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(mask + i * mask_ld + 16 * v));
      const __mmask16 on = _mm256_cmpgt_epi16_mask(a, _mm256_setzero_si256());
      store_bf16(dst + i * ld + 16 * v, _mm512_maskz_mov_ps(on, acc[v]));
    }
  }
};
struct StoreF32 {
  float* dst;
  int64_t ld;
  StoreF32 shifted(int l) const { return {dst + l, ld}; }
  template <int V>
  VNR_BF16_TARGET void operator()(int i, const __m512 (&acc)[V]) const {
    for (int v = 0; v < V; ++v) _mm512_storeu_ps(dst + i * ld + 16 * v, acc[v]);
  }
};
struct AddF32 {
  float* dst;
  int64_t ld;
  int valid;
  AddF32 shifted(int l) const { return {dst + l, ld, valid - l}; }
  template <int V>
  VNR_BF16_TARGET void operator()(int i, const __m512 (&acc)[V]) const {
    for (int v = 0; v < V; ++v) {
      const int n = valid - 16 * v;
      if (n <= 0) break;
      const __mmask16 m = n >= 16 ? __mmask16(0xffff) : __mmask16((1u << n) - 1);
      float* d = dst + i * ld + 16 * v;
      _mm512_mask_storeu_ps(d, m, _mm512_add_ps(_mm512_maskz_loadu_ps(m, d), acc[v]));
    }
  }
};
struct Column {
  float* dst;
  int64_t ld;
  int valid;
  Column shifted(int l) const { return {dst + l * ld, ld, valid - l}; }
  template <int V>
  VNR_BF16_TARGET void operator()(int i, const __m512 (&acc)[V]) const {
    alignas(64) float t[16];
    for (int v = 0; v < V && 16 * v < valid; ++v) {
      _mm512_store_ps(t, acc[v]);
      for (int l = 0; l < 16 && 16 * v + l < valid; ++l) dst[(16 * v + l) * ld + i] = t[l];
    }
  }
};

// S rows x V vectors of accumulators, over all kp pairs.
template <int S, int V, class Epi>
VNR_BF16_TARGET inline void GemmTile(const PairGemm& g, int i0, const Epi& epi) {
  __m512 acc[S][V];
  for (int s = 0; s < S; ++s)
    for (int v = 0; v < V; ++v) acc[s][v] = _mm512_setzero_ps();
  const int* p = reinterpret_cast<const int*>(g.P) + i0 * g.si;
  const uint32_t* q = g.Q;
  for (int k = 0; k < g.kp; ++k, p += g.sk, q += g.ldq) {
    __m512bh b[V];
    for (int v = 0; v < V; ++v) b[v] = (__m512bh)_mm512_loadu_si512(q + 16 * v);
    for (int s = 0; s < S; ++s) {
      const __m512bh a = (__m512bh)_mm512_set1_epi32(p[s * g.si]);
      for (int v = 0; v < V; ++v) acc[s][v] = _mm512_dpbf16_ps(acc[s][v], a, b[v]);
    }
  }
  for (int s = 0; s < S; ++s) epi.template operator()<V>(i0 + s, acc[s]);
}

template <int S, int V, class Epi>
VNR_BF16_TARGET inline void GemmTail(const PairGemm& g, int i0, int rem, const Epi& epi) {
  if constexpr (S > 0) {
    if (rem == S) GemmTile<S, V>(g, i0, epi);
    else GemmTail<S - 1, V>(g, i0, rem, epi);
  }
}

// 12 or 24 accumulators + V operands + a broadcast of the 32 zmm registers (V = 8 runs as two
// halves of 4: 3 rows x 8 would need 33 and spill).
template <int V, class Epi>
VNR_BF16_TARGET void GemmRows(const PairGemm& g, const Epi& epi) {
  constexpr int S = V == 1 ? 12 : 24 / V;
  int i = 0;
  for (; i + S <= g.M; i += S) GemmTile<S, V>(g, i, epi);
  GemmTail<S - 1, V>(g, i, g.M - i, epi);
}

template <class Epi>
VNR_BF16_TARGET void GemmV(const PairGemm& g, const Epi& epi) {
  switch (g.V) {
    case 1: GemmRows<1>(g, epi); break;
    case 2: GemmRows<2>(g, epi); break;
    case 4: GemmRows<4>(g, epi); break;
    default: {
      PairGemm h = g;
      h.V = 4;
      GemmRows<4>(h, epi);
      h.Q = g.Q + 64;
      GemmRows<4>(h, epi.shifted(64));
    }
  }
}

// GCC 12's unmasked unpack/shuffle intrinsics pass an "undefined" vector and warn falsely
// (-Wmaybe-uninitialized); the zero-masked forms with every lane kept are the same instructions.
VNR_BF16_TARGET inline __m512i unpacklo32(__m512i a, __m512i b) { return _mm512_maskz_unpacklo_epi32(0xffff, a, b); }
VNR_BF16_TARGET inline __m512i unpackhi32(__m512i a, __m512i b) { return _mm512_maskz_unpackhi_epi32(0xffff, a, b); }
VNR_BF16_TARGET inline __m512i unpacklo64(__m512i a, __m512i b) { return _mm512_maskz_unpacklo_epi64(0xff, a, b); }
VNR_BF16_TARGET inline __m512i unpackhi64(__m512i a, __m512i b) { return _mm512_maskz_unpackhi_epi64(0xff, a, b); }
template <int kImm>
VNR_BF16_TARGET inline __m512i shuffle128(__m512i a, __m512i b) {
  return _mm512_maskz_shuffle_i32x4(0xffff, a, b, kImm);
}

// r[t] lane l -> r[l] lane t, 32-bit elements.
VNR_BF16_TARGET inline void Transpose16(__m512i (&r)[16]) {
  __m512i t[16], u[16];
  for (int a = 0; a < 16; a += 2) {
    t[a] = unpacklo32(r[a], r[a + 1]);
    t[a + 1] = unpackhi32(r[a], r[a + 1]);
  }
  for (int a = 0; a < 16; a += 4) {
    u[a] = unpacklo64(t[a], t[a + 2]);
    u[a + 1] = unpackhi64(t[a], t[a + 2]);
    u[a + 2] = unpacklo64(t[a + 1], t[a + 3]);
    u[a + 3] = unpackhi64(t[a + 1], t[a + 3]);
  }
  // u[4b + c] holds element c (+4, +8, +12 in the other 128-bit lanes) of rows 4b..4b+3.
  for (int c = 0; c < 4; ++c) {
    t[c] = shuffle128<0x88>(u[c], u[4 + c]);
    t[4 + c] = shuffle128<0xdd>(u[c], u[4 + c]);
    t[8 + c] = shuffle128<0x88>(u[8 + c], u[12 + c]);
    t[12 + c] = shuffle128<0xdd>(u[8 + c], u[12 + c]);
  }
  for (int c = 0; c < 4; ++c) {
    r[c] = shuffle128<0x88>(t[c], t[8 + c]);
    r[8 + c] = shuffle128<0xdd>(t[c], t[8 + c]);
    r[4 + c] = shuffle128<0x88>(t[4 + c], t[12 + c]);
    r[12 + c] = shuffle128<0xdd>(t[4 + c], t[12 + c]);
  }
}

// Word 2l of the result is a's word l, 2l + 1 is b's (lanes 0-15; +16 for the second table).
alignas(64) constexpr int16_t kZipLo[32] = {0, 32, 1, 33, 2,  34, 3,  35, 4,  36, 5,  37, 6,  38, 7,  39,
                                            8, 40, 9, 41, 10, 42, 11, 43, 12, 44, 13, 45, 14, 46, 15, 47};
alignas(64) constexpr int16_t kZipHi[32] = {16, 48, 17, 49, 18, 50, 19, 51, 20, 52, 21, 53, 22, 54, 23, 55,
                                            24, 56, 25, 57, 26, 58, 27, 59, 28, 60, 29, 61, 30, 62, 31, 63};

VNR_BF16_TARGET void ToSmPairs(const float* X, int K, int n, uint32_t* A, int lda) {
  const int kp = (K + 1) / 2;
  for (int s0 = 0; s0 < n; s0 += 16)
    for (int j0 = 0; j0 < kp; j0 += 16) {
      __m512i r[16];
      for (int t = 0; t < 16; ++t) {
        const int j = j0 + t;
        const __m512 lo = j < kp ? _mm512_loadu_ps(X + size_t(2 * j) * n + s0) : _mm512_setzero_ps();
        const __m512 hi = 2 * j + 1 < K ? _mm512_loadu_ps(X + size_t(2 * j + 1) * n + s0) : _mm512_setzero_ps();
        r[t] = bf16_detail::pack_pairs(lo, hi);
      }
      Transpose16(r);
      const int cnt = kp - j0 < 16 ? kp - j0 : 16;
      const __mmask16 m = cnt == 16 ? __mmask16(0xffff) : __mmask16((1u << cnt) - 1);
      for (int t = 0; t < 16; ++t) _mm512_mask_storeu_epi32(A + size_t(s0 + t) * lda + j0, m, r[t]);
    }
}

VNR_BF16_TARGET void ToFeatureMajor(const float* D, int ldd, int K, int n, float* X, int ldx) {
  for (int s0 = 0; s0 < n; s0 += 16)
    for (int c0 = 0; c0 < K; c0 += 16) {
      __m512i r[16];
      for (int t = 0; t < 16; ++t) r[t] = _mm512_loadu_si512(D + size_t(s0 + t) * ldd + c0);
      Transpose16(r);
      for (int c = 0; c < 16 && c0 + c < K; ++c) _mm512_storeu_si512(X + size_t(c0 + c) * ldx + s0, r[c]);
    }
}

VNR_BF16_TARGET void SamplePairs(const uint16_t* A, int lda, int K, int n, uint32_t* S, int lds) {
  const __m512i zl = _mm512_load_si512(kZipLo), zh = _mm512_load_si512(kZipHi);
  for (int j = 0; j < n / 2; ++j) {
    const uint16_t* a = A + size_t(2 * j) * lda;
    const uint16_t* b = a + lda;
    uint32_t* s = S + size_t(j) * lds;
    for (int c0 = 0; c0 < lds; c0 += 32) {
      const int cnt = K - c0 <= 0 ? 0 : (K - c0 >= 32 ? 32 : K - c0);
      const __mmask32 m = cnt == 32 ? __mmask32(0xffffffffu) : __mmask32((1u << cnt) - 1);
      const __m512i va = _mm512_maskz_loadu_epi16(m, a + c0), vb = _mm512_maskz_loadu_epi16(m, b + c0);
      _mm512_storeu_si512(s + c0, _mm512_permutex2var_epi16(va, zl, vb));
      if (c0 + 16 < lds) _mm512_storeu_si512(s + c0 + 16, _mm512_permutex2var_epi16(va, zh, vb));
    }
  }
}

}  // namespace

void pair_gemm(const PairGemm& g) {
  if (!bf16_supported()) fail("bf16 kernels need AVX512-BF16");
  check(g);
  switch (g.out) {
    case PairGemmOut::ReluBf16: GemmV(g, ReluBf16{static_cast<uint16_t*>(g.dst), g.ld}); break;
    case PairGemmOut::MaskBf16: GemmV(g, MaskBf16{static_cast<uint16_t*>(g.dst), g.ld, g.mask, g.mask_ld}); break;
    case PairGemmOut::F32: GemmV(g, StoreF32{static_cast<float*>(g.dst), g.ld}); break;
    case PairGemmOut::AddF32: GemmV(g, AddF32{static_cast<float*>(g.dst), g.ld, g.valid}); break;
    case PairGemmOut::Column: GemmV(g, Column{static_cast<float*>(g.dst), g.ld, g.valid}); break;
  }
}

void feature_major_to_sm_pairs(const float* X, int K, int n, uint32_t* A, int lda) {
  if (!bf16_supported()) fail("bf16 kernels need AVX512-BF16");
  if (n % 16) fail("sample-major conversion needs a multiple of 16 samples, got {}", n);
  ToSmPairs(X, K, n, A, lda);
}

void sm_to_feature_major(const float* D, int ldd, int K, int n, float* X, int ldx) {
  if (!bf16_supported()) fail("bf16 kernels need AVX512-BF16");
  if (n % 16) fail("sample-major conversion needs a multiple of 16 samples, got {}", n);
  ToFeatureMajor(D, ldd, K, n, X, ldx);
}

void sample_pairs(const uint16_t* A, int lda, int K, int n, uint32_t* S, int lds) {
  if (!bf16_supported()) fail("bf16 kernels need AVX512-BF16");
  if (n % 2 || lds % 16 || lds < K) fail("sample_pairs: n must be even and lds a multiple of 16 >= K");
  SamplePairs(A, lda, K, n, S, lds);
}

#else

void pair_gemm(const PairGemm&) { fail("bf16 kernels need AVX512-BF16"); }
void feature_major_to_sm_pairs(const float*, int, int, uint32_t*, int) { fail("bf16 kernels need AVX512-BF16"); }
void sm_to_feature_major(const float*, int, int, int, float*, int) { fail("bf16 kernels need AVX512-BF16"); }
void sample_pairs(const uint16_t*, int, int, int, uint32_t*, int) { fail("bf16 kernels need AVX512-BF16"); }

#endif

}  // namespace vnr::kernels
