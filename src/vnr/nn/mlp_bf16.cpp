// bf16 MLP inference kernels: see mlp_bf16.h. The vector code is x86 AVX512-BF16 only (Highway 1.0.3
// has no vdpbf16ps target), compiled with a function target attribute and chosen at run time.
#include "vnr/nn/mlp_bf16.h"

#include <cmath>
#include <cstring>
#include <vector>

#include "vnr/error.h"

#include "vnr/nn/bf16_simd.h"

namespace vnr::kernels {

uint16_t to_bf16(float f) {
  uint32_t u;
  std::memcpy(&u, &f, 4);
  if ((u & 0x7fffffffu) > 0x7f800000u) return uint16_t((u >> 16) | 0x40u);  // quiet NaN
  u += 0x7fffu + ((u >> 16) & 1u);
  return uint16_t(u >> 16);
}

float from_bf16(uint16_t h) {
  const uint32_t u = uint32_t(h) << 16;
  float f;
  std::memcpy(&f, &u, 4);
  return f;
}

uint32_t bf16_pair(float lo, float hi) { return uint32_t(to_bf16(lo)) | uint32_t(to_bf16(hi)) << 16; }

using bf16_detail::hi_of;
using bf16_detail::lo_of;

void weights_to_bf16_pairs(const float* W, int rows, int K, int ldw, uint32_t* Wp) {
  const int kp = (K + 1) / 2;
  for (int i = 0; i < rows; ++i)
    for (int j = 0; j < kp; ++j) {
      const float* w = W + size_t(i) * ldw + 2 * j;
      Wp[size_t(i) * kp + j] = bf16_pair(w[0], 2 * j + 1 < K ? w[1] : 0.0f);
    }
}

namespace ref {

void matmul_fwd_bf16_linear(const uint32_t* Wp, int rows, int kp, const uint32_t* Xp, float* Y, int n) {
  for (int i = 0; i < rows; ++i)
    for (int s = 0; s < n; ++s) {
      double acc = 0;
      for (int j = 0; j < kp; ++j) {
        const uint32_t w = Wp[size_t(i) * kp + j], x = Xp[size_t(j) * n + s];
        acc += double(lo_of(w)) * lo_of(x) + double(hi_of(w)) * hi_of(x);
      }
      Y[size_t(i) * n + s] = float(acc);
    }
}

void matmul_fwd_bf16_relu(const uint32_t* Wp, int rows, int kp, const uint32_t* Xp, uint32_t* Yp, int n) {
  std::vector<float> Y(size_t(rows) * n);
  matmul_fwd_bf16_linear(Wp, rows, kp, Xp, Y.data(), n);
  for (int i = 0; i < rows; i += 2)
    for (int s = 0; s < n; ++s) {
      const float a = Y[size_t(i) * n + s], b = Y[size_t(i + 1) * n + s];
      Yp[size_t(i / 2) * n + s] = bf16_pair(a > 0 ? a : 0.0f, b > 0 ? b : 0.0f);
    }
}

}  // namespace ref

#if VNR_HAVE_BF16_KERNELS

bool bf16_supported() {
  static const bool ok = __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
                         __builtin_cpu_supports("avx512bf16");
  return ok;
}

bool bf16_preferred() {
  static const bool ok = bf16_supported() && __builtin_cpu_is("amd");
  return ok;
}

namespace {

using bf16_detail::pack_pairs;

// max(x, 0) returns the second operand for NaN: ReLU maps NaN to 0 as the fp32 kernels do. (The
// all-ones maskz form avoids GCC 12's false -Wuninitialized inside _mm512_max_ps.)
VNR_BF16_TARGET inline __m512 relu(__m512 v) { return _mm512_maskz_max_ps(0xffff, v, _mm512_setzero_ps()); }
VNR_BF16_TARGET inline __m512bh bcast(uint32_t w) { return (__m512bh)_mm512_set1_epi32(int(w)); }

// One R x V tile: R output rows x V vectors of 16 samples. wp at row i0's pairs, xp at sample s0,
// out at (row i0, sample s0): pairs row i0/2 (kPairs, R even) or floats row i0.
template <int R, int V, bool kPairs>
VNR_BF16_TARGET inline void Tile(const uint32_t* __restrict wp, int kp, const uint32_t* __restrict xp, size_t n,
                                 void* out) {
  __m512 acc[R][V];
  for (int r = 0; r < R; ++r)
    for (int v = 0; v < V; ++v) acc[r][v] = _mm512_setzero_ps();
  const int* w = reinterpret_cast<const int*>(wp);
  for (int j = 0; j < kp; ++j) {
    __m512bh b[V];
    for (int v = 0; v < V; ++v) b[v] = (__m512bh)_mm512_loadu_si512(xp + size_t(j) * n + 16 * v);
    for (int r = 0; r < R; ++r) {
      const __m512bh a = bcast(uint32_t(w[r * kp + j]));
      for (int v = 0; v < V; ++v) acc[r][v] = _mm512_dpbf16_ps(acc[r][v], a, b[v]);
    }
  }
  if constexpr (kPairs) {
    static_assert(R % 2 == 0, "pairs need an even row count");
    uint32_t* yp = static_cast<uint32_t*>(out);
    for (int r = 0; r < R; r += 2)
      for (int v = 0; v < V; ++v)
        _mm512_storeu_si512(yp + size_t(r / 2) * n + 16 * v, pack_pairs(relu(acc[r][v]), relu(acc[r + 1][v])));
  } else {
    float* y = static_cast<float*>(out);
    for (int r = 0; r < R; ++r)
      for (int v = 0; v < V; ++v) _mm512_storeu_ps(y + size_t(r) * n + 16 * v, acc[r][v]);
  }
}

constexpr int kTileR = 6;  // 6 x 4 = 24 zmm accumulators + 4 operands, as the fp32 kernels
constexpr int kTileV = 4;

template <int V, bool kPairs>
VNR_BF16_TARGET inline void TileRows(int rem, const uint32_t* wp, int kp, const uint32_t* xp, size_t n, void* out) {
  switch (rem) {
    case 2: Tile<2, V, kPairs>(wp, kp, xp, n, out); break;
    case 4: Tile<4, V, kPairs>(wp, kp, xp, n, out); break;
    case 6: Tile<6, V, kPairs>(wp, kp, xp, n, out); break;
    default:
      if constexpr (!kPairs) {
        switch (rem) {
          case 1: Tile<1, V, false>(wp, kp, xp, n, out); break;
          case 3: Tile<3, V, false>(wp, kp, xp, n, out); break;
          case 5: Tile<5, V, false>(wp, kp, xp, n, out); break;
          default: break;
        }
      }
  }
}

template <bool kPairs>
VNR_BF16_TARGET void Gemm(const uint32_t* Wp, int rows, int kp, const uint32_t* Xp, void* out, int n) {
  const size_t nn = size_t(n);
  auto out_at = [&](int i0, size_t s0) -> void* {
    if constexpr (kPairs) return static_cast<uint32_t*>(out) + size_t(i0 / 2) * nn + s0;
    else return static_cast<float*>(out) + size_t(i0) * nn + s0;
  };
  size_t s0 = 0;
  for (; s0 + 16 * kTileV <= nn; s0 += 16 * kTileV)
    for (int i0 = 0; i0 < rows; i0 += kTileR)
      TileRows<kTileV, kPairs>(rows - i0 < kTileR ? rows - i0 : kTileR, Wp + size_t(i0) * kp, kp, Xp + s0, nn,
                               out_at(i0, s0));
  for (; s0 < nn; s0 += 16)  // n is a multiple of 16
    for (int i0 = 0; i0 < rows; i0 += kTileR)
      TileRows<1, kPairs>(rows - i0 < kTileR ? rows - i0 : kTileR, Wp + size_t(i0) * kp, kp, Xp + s0, nn,
                          out_at(i0, s0));
}

VNR_BF16_TARGET void ToPairs(const float* X, int K, int n, uint32_t* P) {
  const int kp = (K + 1) / 2;
  for (int j = 0; j < kp; ++j) {
    const float* lo = X + size_t(2 * j) * n;
    const float* hi = 2 * j + 1 < K ? lo + n : nullptr;
    for (int s = 0; s < n; s += 16)
      _mm512_storeu_si512(P + size_t(j) * n + s, pack_pairs(_mm512_loadu_ps(lo + s),
                                                            hi ? _mm512_loadu_ps(hi + s) : _mm512_setzero_ps()));
  }
}

// 16-wide forward with every activation in registers (the bf16 twin of MlpForward16): lanes =
// samples; each hidden layer packs its 16 ReLU outputs into 8 pair vectors and takes 8 x 16 dot
// products instead of 16 x 16 FMAs.
VNR_BF16_TARGET void Forward16(const uint32_t* W0, int k0, const uint32_t* const* Wh, int n_mid, const uint32_t* Wout,
                               const float* X0, int n, float* out) {
  constexpr int kW = 16;
  const __m512 zero = _mm512_setzero_ps();
  const int kp0 = (k0 + 1) / 2;
  for (size_t s0 = 0; s0 + 16 <= size_t(n); s0 += 16) {
    __m512 h[kW];
    for (int o = 0; o < kW; ++o) h[o] = zero;
    for (int j = 0; j < kp0; ++j) {
      const __m512 lo = _mm512_loadu_ps(X0 + size_t(2 * j) * n + s0);
      const __m512 hi = 2 * j + 1 < k0 ? _mm512_loadu_ps(X0 + size_t(2 * j + 1) * n + s0) : zero;
      const __m512bh x = (__m512bh)pack_pairs(lo, hi);
      for (int o = 0; o < kW; ++o) h[o] = _mm512_dpbf16_ps(h[o], bcast(W0[o * kp0 + j]), x);
    }
    __m512bh p[kW / 2];
    for (int j = 0; j < kW / 2; ++j) p[j] = (__m512bh)pack_pairs(relu(h[2 * j]), relu(h[2 * j + 1]));
    for (int l = 0; l < n_mid; ++l) {
      const uint32_t* W = Wh[l];
      for (int o = 0; o < kW; ++o) h[o] = zero;
      for (int j = 0; j < kW / 2; ++j)
        for (int o = 0; o < kW; ++o) h[o] = _mm512_dpbf16_ps(h[o], bcast(W[o * (kW / 2) + j]), p[j]);
      for (int j = 0; j < kW / 2; ++j) p[j] = (__m512bh)pack_pairs(relu(h[2 * j]), relu(h[2 * j + 1]));
    }
    __m512 y0 = zero, y1 = zero;  // two chains: the output's 8 dot products would otherwise wait on each other
    for (int j = 0; j < kW / 2; j += 2) {
      y0 = _mm512_dpbf16_ps(y0, bcast(Wout[j]), p[j]);
      y1 = _mm512_dpbf16_ps(y1, bcast(Wout[j + 1]), p[j + 1]);
    }
    _mm512_storeu_ps(out + s0, _mm512_add_ps(y0, y1));
  }
}

}  // namespace

void mlp_forward_16_bf16(const uint32_t* W0, int k0, const uint32_t* const* Wh, int n_mid, const uint32_t* Wout,
                         const float* X0, int n, float* out) {
  if (!bf16_supported()) fail("bf16 kernels need AVX512-BF16");
  Forward16(W0, k0, Wh, n_mid, Wout, X0, n, out);
}

void activations_to_bf16_pairs(const float* X, int K, int n, uint32_t* P) {
  if (!bf16_supported()) fail("bf16 kernels need AVX512-BF16");
  ToPairs(X, K, n, P);
}

void matmul_fwd_bf16_relu(const uint32_t* Wp, int rows, int kp, const uint32_t* Xp, uint32_t* Yp, int n) {
  if (!bf16_supported()) fail("bf16 kernels need AVX512-BF16");
  Gemm<true>(Wp, rows, kp, Xp, Yp, n);
}

void matmul_fwd_bf16_linear(const uint32_t* Wp, int rows, int kp, const uint32_t* Xp, float* Y, int n) {
  if (!bf16_supported()) fail("bf16 kernels need AVX512-BF16");
  Gemm<false>(Wp, rows, kp, Xp, Y, n);
}

#else

bool bf16_supported() { return false; }
bool bf16_preferred() { return false; }
void mlp_forward_16_bf16(const uint32_t*, int, const uint32_t* const*, int, const uint32_t*, const float*, int, float*) {
  fail("bf16 kernels need AVX512-BF16");
}
void activations_to_bf16_pairs(const float*, int, int, uint32_t*) { fail("bf16 kernels need AVX512-BF16"); }
void matmul_fwd_bf16_relu(const uint32_t*, int, int, const uint32_t*, uint32_t*, int) {
  fail("bf16 kernels need AVX512-BF16");
}
void matmul_fwd_bf16_linear(const uint32_t*, int, int, const uint32_t*, float*, int) {
  fail("bf16 kernels need AVX512-BF16");
}

#endif

}  // namespace vnr::kernels
