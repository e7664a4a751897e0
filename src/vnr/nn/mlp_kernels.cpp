// Hot MLP kernels: Highway dynamic dispatch over SIMD targets (AVX3 on the target machine).
// All three kernels are single-threaded and allocation-free: the trainer calls them per chunk from
// inside its own parallel loop.
//
// fwd and bwd_data share one register-blocked micro-kernel computing
//   Out[i*n + s] = epilogue(sum_k A(i, k) * B[k*n + s])
// with R output rows x V vectors of samples in accumulators (AVX-512: 6 x 4 = 24 zmm). Each k step
// loads V vectors of B and broadcasts R scalars of A from memory (vbroadcastss zmm, m32), each
// broadcast feeding V FMAs, so loads stay well below the FMA rate.
//   fwd:      A(i, k) = W[i*cols + k]   (row-strided broadcasts), B = X,  epilogue ReLU or identity
//   bwd_data: A(i, k) = W[k*cols + i]   (W^T without transposing: contiguous broadcasts), B = dY,
//             epilogue mask > 0.
// bwd_weights keeps a 4x4 block of (r, c) dot products over s in 16 vector accumulators and reduces
// them to one vector with a shuffle tree once per block (AVX-512), instead of 16 separate
// horizontal sums.

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "vnr/nn/mlp_kernels.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

#include <cstddef>

#include "vnr/nn/mlp_kernels.h"

HWY_BEFORE_NAMESPACE();
namespace vnr::kernels {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

using DF = hn::ScalableTag<float>;

#if HWY_TARGET == HWY_AVX3 || HWY_TARGET == HWY_AVX3_DL
#define VNR_MLP_WIDE 1
// 32 zmm registers: 6 rows x 4 vectors = 24 accumulators + 4 B vectors + spare.
constexpr int kTileR = 6;
constexpr int kTileV = 4;
#else
#define VNR_MLP_WIDE 0
// 16 registers (AVX2/SSE): 3 x 4 = 12 accumulators + 4 B vectors.
constexpr int kTileR = 3;
constexpr int kTileV = 4;
#endif

enum class Epi { kNone, kRelu, kMask };

// One R x V tile. a points at A(i0, 0); b at B[s0]; out / mask at row i0, sample s0.
// kAT: A is stored transposed (A(i, k) = a[k*lda + i]), else A(i, k) = a[i*lda + k].
// The epilogue is a template parameter so that the accumulators stay in registers through it.
template <int R, int V, bool kAT, Epi E>
HWY_INLINE void Tile(const float* HWY_RESTRICT a, size_t lda, const float* HWY_RESTRICT b, size_t n,
                     int K, float* HWY_RESTRICT out, const float* HWY_RESTRICT mask) {
  const DF d;
  const size_t N = hn::Lanes(d);
  using V_t = hn::Vec<DF>;
  // Few accumulators cannot hide the FMA latency (4 cycles x 2 pipes): then keep a second set
  // for odd k and add the two at the end.
  constexpr int kSets = R * V < 8 ? 2 : 1;
  V_t acc[kSets][R][V];
  for (int t = 0; t < kSets; ++t)
    for (int r = 0; r < R; ++r)
      for (int v = 0; v < V; ++v) acc[t][r][v] = hn::Zero(d);

  auto load_b = [&](V_t* bv) {
    for (int v = 0; v < V; ++v) bv[v] = hn::LoadU(d, b + v * N);
    b += n;
  };
  // A(r, k) for kAT: constant offsets from one pointer stepping by lda; otherwise one row pointer
  // per r stepping by one float (the compiler keeps them in GPRs).
  const float* HWY_RESTRICT ar[R];
  for (int r = 0; r < R; ++r) ar[r] = a + r * lda;
  auto step = [&](int t) {
    V_t bv[V];
    load_b(bv);
    for (int r = 0; r < R; ++r) {
      const V_t w = hn::Set(d, kAT ? a[r] : *ar[r]);
      for (int v = 0; v < V; ++v) acc[t][r][v] = hn::MulAdd(w, bv[v], acc[t][r][v]);
      if constexpr (!kAT) ++ar[r];
    }
    if constexpr (kAT) a += lda;
  };
  int k = 0;
  if constexpr (kSets == 2) {
    for (; k + 2 <= K; k += 2) {
      step(0);
      step(1);
    }
  }
  for (; k < K; ++k) step(0);

  const V_t zero = hn::Zero(d);
  for (int r = 0; r < R; ++r) {
    for (int v = 0; v < V; ++v) {
      V_t y = acc[0][r][v];
      if constexpr (kSets == 2) y = hn::Add(y, acc[kSets - 1][r][v]);
      if constexpr (E == Epi::kRelu) {
        y = hn::Max(y, zero);  // also maps NaN to 0, like the reference's (y > 0 ? y : 0)
      } else if constexpr (E == Epi::kMask) {
        y = hn::IfThenElseZero(hn::Gt(hn::LoadU(d, mask + r * n + v * N), zero), y);
      }
      hn::StoreU(y, d, out + r * n + v * N);
    }
  }
}

// Rows i0 .. i0+rem-1 (rem < kTileR) with V vectors.
template <int V, bool kAT, Epi E>
HWY_INLINE void TileRem(int rem, const float* a, size_t lda, const float* b, size_t n, int K,
                        float* out, const float* mask) {
  static_assert(kTileR <= 8, "extend the switch");
  switch (rem) {
    case 1: Tile<1, V, kAT, E>(a, lda, b, n, K, out, mask); break;
    case 2: if constexpr (kTileR > 2) Tile<2, V, kAT, E>(a, lda, b, n, K, out, mask); break;
    case 3: if constexpr (kTileR > 3) Tile<3, V, kAT, E>(a, lda, b, n, K, out, mask); break;
    case 4: if constexpr (kTileR > 4) Tile<4, V, kAT, E>(a, lda, b, n, K, out, mask); break;
    case 5: if constexpr (kTileR > 5) Tile<5, V, kAT, E>(a, lda, b, n, K, out, mask); break;
    case 6: if constexpr (kTileR > 6) Tile<6, V, kAT, E>(a, lda, b, n, K, out, mask); break;
    case 7: if constexpr (kTileR > 7) Tile<7, V, kAT, E>(a, lda, b, n, K, out, mask); break;
    default: break;
  }
}

// Out (M x n) = epi(A (M x K) * B (K x n)). A(i, k) at a[i*lda + k] (kAT false) or a[k*lda + i].
template <bool kAT, Epi E>
HWY_NOINLINE void Gemm(const float* a, size_t lda, int M, int K, const float* b, float* out, int n,
                       const float* mask) {
  const DF d;
  const size_t N = hn::Lanes(d);
  const size_t nn = static_cast<size_t>(n);
  // Offset of A(i0, 0) for row block i0.
  auto a_at = [&](int i0) { return kAT ? a + i0 : a + static_cast<size_t>(i0) * lda; };
  auto mask_at = [&](int i0, size_t s0) { return mask ? mask + i0 * nn + s0 : nullptr; };

  // Sample blocks outermost: the K x (V*N) panel of B stays in L1 while all row blocks use it.
  const size_t sv = kTileV * N;
  size_t s0 = 0;
  for (; s0 + sv <= nn; s0 += sv) {
    int i0 = 0;
    for (; i0 + kTileR <= M; i0 += kTileR)
      Tile<kTileR, kTileV, kAT, E>(a_at(i0), lda, b + s0, nn, K, out + i0 * nn + s0,
                                   mask_at(i0, s0));
    if (i0 < M)
      TileRem<kTileV, kAT, E>(M - i0, a_at(i0), lda, b + s0, nn, K, out + i0 * nn + s0,
                              mask_at(i0, s0));
  }
  for (; s0 + N <= nn; s0 += N) {  // leftover single vectors
    int i0 = 0;
    for (; i0 + kTileR <= M; i0 += kTileR)
      Tile<kTileR, 1, kAT, E>(a_at(i0), lda, b + s0, nn, K, out + i0 * nn + s0, mask_at(i0, s0));
    if (i0 < M)
      TileRem<1, kAT, E>(M - i0, a_at(i0), lda, b + s0, nn, K, out + i0 * nn + s0, mask_at(i0, s0));
  }
  // Scalar tail: only when n is not a multiple of the vector length (the contract says it is).
  for (; s0 < nn; ++s0) {
    for (int i = 0; i < M; ++i) {
      float sum = 0.0f;
      for (int k = 0; k < K; ++k) {
        const float aik = kAT ? a[static_cast<size_t>(k) * lda + i] : a[static_cast<size_t>(i) * lda + k];
        sum += aik * b[k * nn + s0];
      }
      if (E == Epi::kRelu) sum = sum > 0.0f ? sum : 0.0f;
      if (E == Epi::kMask && !(mask[i * nn + s0] > 0.0f)) sum = 0.0f;
      out[i * nn + s0] = sum;
    }
  }
}

void MatmulFwd(const float* W, int rows, int cols, const float* X, float* Y, int n, bool relu, int ldw) {
  if (relu)
    Gemm<false, Epi::kRelu>(W, static_cast<size_t>(ldw), rows, cols, X, Y, n, nullptr);
  else
    Gemm<false, Epi::kNone>(W, static_cast<size_t>(ldw), rows, cols, X, Y, n, nullptr);
}

void MatmulBwdData(const float* W, int rows, int cols, const float* dY, const float* mask,
                   float* dX, int n, int ldw) {
  if (mask)
    Gemm<true, Epi::kMask>(W, static_cast<size_t>(ldw), cols, rows, dY, dX, n, mask);
  else
    Gemm<true, Epi::kNone>(W, static_cast<size_t>(ldw), cols, rows, dY, dX, n, nullptr);
}

// ---- bwd_weights ----

// Generic R x C block: dW[r][c] += sum_s dY[r][s] * X[c][s], one horizontal sum per accumulator.
template <int R, int C>
HWY_INLINE void WTileGeneric(const float* HWY_RESTRICT dy, const float* HWY_RESTRICT x, size_t n,
                             float* HWY_RESTRICT dw, size_t ldw) {
  const DF d;
  const size_t N = hn::Lanes(d);
  using V_t = hn::Vec<DF>;
  V_t acc[R][C];
  for (int r = 0; r < R; ++r)
    for (int c = 0; c < C; ++c) acc[r][c] = hn::Zero(d);
  size_t s = 0;
  for (; s + N <= n; s += N) {
    V_t xv[C];
    for (int c = 0; c < C; ++c) xv[c] = hn::LoadU(d, x + c * n + s);
    for (int r = 0; r < R; ++r) {
      const V_t yv = hn::LoadU(d, dy + r * n + s);
      for (int c = 0; c < C; ++c) acc[r][c] = hn::MulAdd(yv, xv[c], acc[r][c]);
    }
  }
  for (int r = 0; r < R; ++r) {
    for (int c = 0; c < C; ++c) {
      float sum = hn::GetLane(hn::SumOfLanes(d, acc[r][c]));
      for (size_t t = s; t < n; ++t) sum += dy[r * n + t] * x[c * n + t];  // n % N tail
      dw[r * ldw + c] += sum;
    }
  }
}

#if VNR_MLP_WIDE
// 4 x 4 block on 16-lane vectors. The 16 accumulators a[c*4 + r] are reduced by a 4-level tree
// (halves, 128-bit blocks, pairs, lanes) into one vector whose block b holds row kRowOfBlock[b],
// columns 0..3: 15 adds + 30 shuffles/blends instead of 16 full horizontal reductions.
HWY_INLINE void WTile4x4(const float* HWY_RESTRICT dy, const float* HWY_RESTRICT x, size_t n,
                         float* HWY_RESTRICT dw, size_t ldw) {
  const DF d;
  constexpr size_t N = 16;
  using V_t = hn::Vec<DF>;
  V_t acc[16];
  for (int j = 0; j < 16; ++j) acc[j] = hn::Zero(d);
  size_t s = 0;
  for (; s + N <= n; s += N) {
    V_t xv[4];
    for (int c = 0; c < 4; ++c) xv[c] = hn::LoadU(d, x + c * n + s);
    for (int r = 0; r < 4; ++r) {
      const V_t yv = hn::LoadU(d, dy + r * n + s);
      for (int c = 0; c < 4; ++c) acc[c * 4 + r] = hn::MulAdd(yv, xv[c], acc[c * 4 + r]);
    }
  }
  // Level 1: u[m] lanes 0-7 = partial sums of acc[2m], lanes 8-15 of acc[2m+1].
  V_t u[8];
  for (int m = 0; m < 8; ++m)
    u[m] = hn::Add(hn::ConcatLowerLower(d, acc[2 * m + 1], acc[2 * m]),
                   hn::ConcatUpperUpper(d, acc[2 * m + 1], acc[2 * m]));
  // Level 2: w[p] blocks 0..3 = 4-lane partial sums of acc[4p + {0, 2, 1, 3}].
  V_t w[4];
  for (int p = 0; p < 4; ++p) {
    const V_t x0 = u[2 * p], y0 = u[2 * p + 1];
    w[p] = hn::Add(hn::OddEvenBlocks(y0, x0), hn::SwapAdjacentBlocks(hn::OddEvenBlocks(x0, y0)));
  }
  // Level 3: z[q] per block = [X, Y, X, Y] 2-lane partial sums of (w[2q], w[2q+1]).
  V_t z[2];
  for (int q = 0; q < 2; ++q)
    z[q] = hn::Add(hn::InterleaveLower(d, w[2 * q], w[2 * q + 1]),
                   hn::InterleaveUpper(d, w[2 * q], w[2 * q + 1]));
  // Level 4: per block [w0, w1, w2, w3] full sums, via 64-bit interleaves.
  const hn::Repartition<double, DF> dd;
  const auto z0 = hn::BitCast(dd, z[0]), z1 = hn::BitCast(dd, z[1]);
  const V_t t = hn::Add(hn::BitCast(d, hn::InterleaveLower(dd, z0, z1)),
                        hn::BitCast(d, hn::InterleaveUpper(dd, z0, z1)));
  // Lane 4b + p = sum of acc[4p + kRowOfBlock[b]] = dW(row kRowOfBlock[b], col p).
  HWY_ALIGN float tmp[16];
  hn::Store(t, d, tmp);
  constexpr int kRowOfBlock[4] = {0, 2, 1, 3};
  const hn::Full128<float> d4;
  for (int b = 0; b < 4; ++b) {
    float* row = dw + kRowOfBlock[b] * ldw;
    hn::StoreU(hn::Add(hn::LoadU(d4, row), hn::Load(d4, tmp + 4 * b)), d4, row);
  }
  for (size_t t2 = s; t2 < n; ++t2)  // n % 16 tail (not reached when n is a multiple of 16)
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) dw[r * ldw + c] += dy[r * n + t2] * x[c * n + t2];
}
#endif

template <int R>
HWY_INLINE void WRowBlock(const float* dy, const float* X, int cols, size_t n, float* dw,
                          size_t ldw) {
  int c0 = 0;
#if VNR_MLP_WIDE
  if constexpr (R == 4) {
    for (; c0 + 4 <= cols; c0 += 4) WTile4x4(dy, X + c0 * n, n, dw + c0, ldw);
  }
#endif
  if constexpr (R == 1) {  // 8 independent accumulators to cover the FMA latency
    for (; c0 + 8 <= cols; c0 += 8) WTileGeneric<1, 8>(dy, X + c0 * n, n, dw + c0, ldw);
  }
  for (; c0 + 4 <= cols; c0 += 4) WTileGeneric<R, 4>(dy, X + c0 * n, n, dw + c0, ldw);
  switch (cols - c0) {
    case 1: WTileGeneric<R, 1>(dy, X + c0 * n, n, dw + c0, ldw); break;
    case 2: WTileGeneric<R, 2>(dy, X + c0 * n, n, dw + c0, ldw); break;
    case 3: WTileGeneric<R, 3>(dy, X + c0 * n, n, dw + c0, ldw); break;
    default: break;
  }
}

void MatmulBwdWeights(const float* dY, int rows, const float* X, int cols, int n, float* dW, int ldw_) {
  const size_t nn = static_cast<size_t>(n), ldw = static_cast<size_t>(ldw_);
  int r0 = 0;
  for (; r0 + 4 <= rows; r0 += 4) WRowBlock<4>(dY + r0 * nn, X, cols, nn, dW + r0 * ldw, ldw);
  switch (rows - r0) {
    case 1: WRowBlock<1>(dY + r0 * nn, X, cols, nn, dW + r0 * ldw, ldw); break;
    case 2: WRowBlock<2>(dY + r0 * nn, X, cols, nn, dW + r0 * ldw, ldw); break;
    case 3: WRowBlock<3>(dY + r0 * nn, X, cols, nn, dW + r0 * ldw, ldw); break;
    default: break;
  }
}

// Whole forward pass of a 16-wide ReLU MLP with one output, lanes = samples, every activation in
// registers: a 16-wide network's GEMMs are too small (K = 8-16) for the tiled kernels to reach the
// FMA peak, while here each weight is one broadcast-FMA and nothing is stored between layers.
void MlpForward16(const float* W0, int k0, int ldw0, const float* const* Wh, int n_mid, const float* Wout,
                  const float* X0, int n, float* out) {
  constexpr int kW = 16;
  const DF d;
  const size_t N = hn::Lanes(d);
  using V = hn::Vec<DF>;
  const V zero = hn::Zero(d);
  for (size_t s0 = 0; s0 + N <= size_t(n); s0 += N) {
    V h[kW];
    for (int o = 0; o < kW; ++o) h[o] = zero;
    for (int c = 0; c < k0; ++c) {
      const V x = hn::LoadU(d, X0 + size_t(c) * n + s0);
      for (int o = 0; o < kW; ++o) h[o] = hn::MulAdd(hn::Set(d, W0[size_t(o) * ldw0 + c]), x, h[o]);
    }
    for (int o = 0; o < kW; ++o) h[o] = hn::Max(h[o], zero);
    for (int l = 0; l < n_mid; ++l) {
      const float* W = Wh[l];
      V g[kW];
      for (int o = 0; o < kW; ++o) g[o] = zero;
      for (int i = 0; i < kW; ++i)
        for (int o = 0; o < kW; ++o) g[o] = hn::MulAdd(hn::Set(d, W[o * kW + i]), h[i], g[o]);
      for (int o = 0; o < kW; ++o) h[o] = hn::Max(g[o], zero);
    }
    V y = zero;
    for (int i = 0; i < kW; ++i) y = hn::MulAdd(hn::Set(d, Wout[i]), h[i], y);
    hn::StoreU(y, d, out + s0);
  }
}

const char* TargetNameImpl() { return hwy::TargetName(HWY_TARGET); }

#undef VNR_MLP_WIDE
}  // namespace HWY_NAMESPACE
}  // namespace vnr::kernels
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace vnr::kernels {

HWY_EXPORT(MatmulFwd);
HWY_EXPORT(MatmulBwdData);
HWY_EXPORT(MatmulBwdWeights);
HWY_EXPORT(TargetNameImpl);
HWY_EXPORT(MlpForward16);

void mlp_forward_16(const float* W0, int k0, int ldw0, const float* const* Wh, int n_mid, const float* Wout,
                    const float* X0, int n, float* out) {
  HWY_DYNAMIC_DISPATCH(MlpForward16)(W0, k0, ldw0, Wh, n_mid, Wout, X0, n, out);
}

void matmul_fwd(const float* W, int rows, int cols, const float* X, float* Y, int n, bool relu, int ldw) {
  HWY_DYNAMIC_DISPATCH(MatmulFwd)(W, rows, cols, X, Y, n, relu, ldw > 0 ? ldw : cols);
}
void matmul_bwd_data(const float* W, int rows, int cols, const float* dY, const float* mask,
                     float* dX, int n, int ldw) {
  HWY_DYNAMIC_DISPATCH(MatmulBwdData)(W, rows, cols, dY, mask, dX, n, ldw > 0 ? ldw : cols);
}
void matmul_bwd_weights(const float* dY, int rows, const float* X, int cols, int n, float* dW, int ldw) {
  HWY_DYNAMIC_DISPATCH(MatmulBwdWeights)(dY, rows, X, cols, n, dW, ldw > 0 ? ldw : cols);
}
const char* simd_target_name() { return HWY_DYNAMIC_DISPATCH(TargetNameImpl)(); }

// Portable scalar reference (compiled once): plain loops in the order the formulas read.
namespace ref {
void matmul_fwd(const float* W, int rows, int cols, const float* X, float* Y, int n, bool relu, int ldw) {
  const size_t ld = size_t(ldw > 0 ? ldw : cols);
  for (int r = 0; r < rows; ++r)
    for (int s = 0; s < n; ++s) {
      float sum = 0.0f;
      for (int c = 0; c < cols; ++c) sum += W[size_t(r) * ld + c] * X[size_t(c) * n + s];
      Y[size_t(r) * n + s] = relu ? (sum > 0.0f ? sum : 0.0f) : sum;
    }
}
void matmul_bwd_data(const float* W, int rows, int cols, const float* dY, const float* mask,
                     float* dX, int n, int ldw) {
  const size_t ld = size_t(ldw > 0 ? ldw : cols);
  for (int c = 0; c < cols; ++c)
    for (int s = 0; s < n; ++s) {
      float sum = 0.0f;
      for (int r = 0; r < rows; ++r) sum += W[size_t(r) * ld + c] * dY[size_t(r) * n + s];
      // Select rather than multiply by 0/1, so a masked-out gradient is exactly 0 even if inf.
      dX[size_t(c) * n + s] = (mask == nullptr || mask[size_t(c) * n + s] > 0.0f) ? sum : 0.0f;
    }
}
void matmul_bwd_weights(const float* dY, int rows, const float* X, int cols, int n, float* dW, int ldw) {
  const size_t ld = size_t(ldw > 0 ? ldw : cols);
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) {
      float sum = 0.0f;
      for (int s = 0; s < n; ++s) sum += dY[size_t(r) * n + s] * X[size_t(c) * n + s];
      dW[size_t(r) * ld + c] += sum;
    }
}
}  // namespace ref

}  // namespace vnr::kernels
#endif  // HWY_ONCE
