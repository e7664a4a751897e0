// Per-target compilation of the grid and Adam loops (see cpu_kernels.h).
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "vnr/nn/cpu_kernels.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

#include <cmath>
#include <cstring>
#include "vnr/core/gather-inl.h"
#include "vnr/nn/cpu_kernels.h"
#include "vnr/nn/lattice-inl.h"

HWY_BEFORE_NAMESPACE();
namespace vnr::kernels {
namespace HWY_NAMESPACE {

namespace hn = hwy::HWY_NAMESPACE;
using DF = hn::ScalableTag<float>;
using DU = hn::RebindToUnsigned<DF>;
using DI = hn::RebindToSigned<DF>;
constexpr size_t kMaxLanes = 64 / sizeof(float);  // 512-bit vectors at most

// Lattice cell i, weight t of the upper corner (sv) and 1 - t (sm) per axis, for Lanes(DF) samples.
HWY_INLINE void LatticeCoords(const GridLevel& L, bool smooth, const float* x, const float* y, const float* z,
                              hn::Vec<DU>* i, hn::Vec<DF>* sv, hn::Vec<DF>* sm) {
  const DF df;
  const float* in[3] = {x, y, z};
  for (int d = 0; d < 3; ++d)
    vnr::HWY_NAMESPACE::LatticeAxis(df, hn::Set(df, L.scale), hn::LoadU(df, in[d]), smooth, &i[d], &sv[d], &sm[d]);
}

// Vectorised corner computation for one level and Lanes(DF) samples: entries and weights of the 8
// corners, with exactly the operation order of grid_corners() (so results are bit-identical).
// Valid for Linear/Smoothstep interpolation, Hash or Dense levels, and inputs in [0, 1] (then every
// dense index is below 2 n_l and one conditional subtraction replaces the modulo).
struct CornerBlock {
  alignas(64) uint32_t entry[8][kMaxLanes];
  alignas(64) float weight[8][kMaxLanes];
};

HWY_INLINE void CornersVec(const GridLevel& L, bool smooth, const float* x, const float* y, const float* z,
                           CornerBlock& cb) {
  const DF df;
  const DU du;
  hn::Vec<DU> i[3];
  hn::Vec<DF> sv[3], sm[3];
  LatticeCoords(L, smooth, x, y, z, i, sv, sm);
  const auto res = hn::Set(du, L.res), res2 = hn::Set(du, L.res * L.res);
  const auto n = hn::Set(du, L.n_entries), mask = hn::Set(du, L.pow2_mask);
  const auto p1 = hn::Set(du, 2654435761u), p2 = hn::Set(du, 805459861u), c1 = hn::Set(du, 1u);
  for (int k = 0; k < 8; ++k) {
    const auto cx = (k & 1) ? hn::Add(i[0], c1) : i[0];
    const auto cy = (k & 2) ? hn::Add(i[1], c1) : i[1];
    const auto cz = (k & 4) ? hn::Add(i[2], c1) : i[2];
    hn::Vec<DU> idx;
    if (L.hashed) idx = hn::Xor(hn::Xor(cx, hn::Mul(cy, p1)), hn::Mul(cz, p2));
    else idx = hn::Add(hn::Add(cx, hn::Mul(cy, res)), hn::Mul(cz, res2));
    if (L.pow2_mask) idx = hn::And(idx, mask);
    else idx = hn::Min(idx, hn::Sub(idx, n));  // unsigned: idx - n wraps above idx when idx < n
    hn::Store(idx, du, cb.entry[k]);
    const auto w = hn::Mul(hn::Mul((k & 1) ? sv[0] : sm[0], (k & 2) ? sv[1] : sm[1]), (k & 4) ? sv[2] : sm[2]);
    hn::Store(w, df, cb.weight[k]);
  }
}

// Prefetch into L2 (prefetcht1), not L1: a block issues 128 prefetches, far more than the L1's miss
// buffers, so L1 prefetches are largely lost.
template <int F, typename P>
HWY_INLINE void PrefetchCorners(const P* lt, const CornerBlock& cb, size_t N, bool enabled = true) {
  if (!enabled) return;
  for (int k = 0; k < 8; ++k)
    for (size_t s = 0; s < N; ++s) __builtin_prefetch(lt + uint64_t(cb.entry[k][s]) * F, 0, 2);
}

// The vector path applies when every input of the block is in [0, 1] (no negative or far lattice
// coordinates) and the level is not tiled; otherwise the scalar single-source path runs.
HWY_INLINE bool BlockInUnitCube(const float* x, const float* y, const float* z, size_t N) {
  const DF df;
  const auto zero = hn::Zero(df), one = hn::Set(df, 1.0f);
  auto ok = hn::And(hn::Ge(hn::LoadU(df, x), zero), hn::Le(hn::LoadU(df, x), one));
  ok = hn::And(ok, hn::And(hn::Ge(hn::LoadU(df, y), zero), hn::Le(hn::LoadU(df, y), one)));
  ok = hn::And(ok, hn::And(hn::Ge(hn::LoadU(df, z), zero), hn::Le(hn::LoadU(df, z), one)));
  (void)N;
  return hn::AllTrue(df, ok);
}

// Number of leading full blocks of N samples that take the vector path.
HWY_INLINE int ValidBlocks(bool vec_ok, const float* x, const float* y, const float* z, int64_t n, size_t N) {
  if (!vec_ok) return 0;
  int nb = 0;
  while (int64_t(nb + 1) * int64_t(N) <= n && BlockInUnitCube(x + nb * N, y + nb * N, z + nb * N, N)) ++nb;
  return nb;
}

// Prefetch distance in blocks of samples (one block of the large levels takes about one memory
// latency to gather).
#ifndef VNR_PREFETCH_BLOCKS
#define VNR_PREFETCH_BLOCKS 2
#endif
constexpr int kAhead = VNR_PREFETCH_BLOCKS;

HWY_INLINE bool VectorPathOk(const GridLevel& L, const GridLayout& g) {
  // Without hardware FMA, Highway's MulAdd rounds twice; the scalar path (fmaf, correctly rounded)
  // keeps results bit-identical to the reference on every target.
  if (!HWY_NATIVE_FMA) return false;
  if (g.interpolation == Interpolation::Nearest) return false;
  // Dense levels need idx < 2 n_l for the single subtraction: true when n_l >= res^3 (not tiled).
  if (!L.hashed && !L.pow2_mask && uint64_t(L.n_entries) < uint64_t(L.res) * L.res * L.res) return false;
  return true;
}

template <int F>
using DFF = hn::CappedTag<float, F>;  // the F features of one grid entry
template <int F>
using DHF = hn::Rebind<hwy::float16_t, DFF<F>>;

// The software pipeline shared by the forward gather and the backward scatter: for the first nb
// blocks of N samples, the corners of block b + kAhead are computed and their table lines
// prefetched while body(block b's corners, b * N) runs, so the random accesses of the large levels
// overlap instead of waiting one by one. `table` is the level's base (fp16 table or fp32 gradient).
template <int F, typename P, typename Body>
HWY_INLINE void PipelinedBlocks(const GridLevel& L, bool smooth, const float* x, const float* y, const float* z,
                                int nb, size_t N, const P* table, bool pf, Body&& body) {
  CornerBlock cbs[kAhead + 1];
  for (int b = 0; b < nb && b < kAhead; ++b) {
    CornersVec(L, smooth, x + b * N, y + b * N, z + b * N, cbs[b]);
    PrefetchCorners<F>(table, cbs[b], N, pf);
  }
  for (int b = 0; b < nb; ++b) {
    if (b + kAhead < nb) {
      const size_t sa = size_t(b + kAhead) * N;
      CornerBlock& ahead = cbs[(b + kAhead) % (kAhead + 1)];
      CornersVec(L, smooth, x + sa, y + sa, z + sa, ahead);
      PrefetchCorners<F>(table, ahead, N, pf);
    }
    body(cbs[b % (kAhead + 1)], size_t(b) * N);
  }
}

// One block of N samples from its corner block: per sample and corner, F features with one fp16
// load, one conversion and one FMA per vector of features (accumulated in corner order k = 0..7).
template <int F>
HWY_INLINE void GatherBlock(const uint16_t* lt, const CornerBlock& cur, size_t N, float* out, int n, size_t s0) {
  const DFF<F> dff;
  const DHF<F> dhf;
  constexpr size_t NV = (F + hn::MaxLanes(DFF<F>()) - 1) / hn::MaxLanes(DFF<F>());
  const size_t NF = hn::Lanes(dff);
  for (size_t s = 0; s < N; ++s) {
    hn::Vec<DFF<F>> acc[NV];
    for (size_t v = 0; v < NV; ++v) acc[v] = hn::Zero(dff);
    for (int k = 0; k < 8; ++k) {
      const auto* th = reinterpret_cast<const hwy::float16_t*>(lt + uint64_t(cur.entry[k][s]) * F);
      const auto w = hn::Set(dff, cur.weight[k][s]);
      for (size_t v = 0; v < NV; ++v) acc[v] = hn::MulAdd(w, hn::PromoteTo(dff, hn::LoadU(dhf, th + v * NF)), acc[v]);
    }
    alignas(64) float tmp[NV * kMaxLanes];
    for (size_t v = 0; v < NV; ++v) hn::StoreU(acc[v], dff, tmp + v * NF);
    for (int f = 0; f < F; ++f) out[f * n + s0 + s] = tmp[f];
  }
}

#if HWY_TARGET != HWY_SCALAR
// Up to 4 vectors of a small level's 32-bit entries, so that a lookup is a few in-register
// permutes instead of a gather (level 0 of most configs: 4^3 = 64 entries, 256 bytes).
struct RegisterTable {
  static constexpr int kMaxVecs = 4;
  hn::Vec<DU> t[kMaxVecs];
  int vecs = 0;  // 0: the table does not fit
};

HWY_INLINE RegisterTable LoadRegisterTable(const uint16_t* lt, uint32_t n_entries) {
  const DU du;
  const size_t N = hn::Lanes(du);
  RegisterTable r;
  if (n_entries > RegisterTable::kMaxVecs * N) return r;
  r.vecs = int((n_entries + N - 1) / N);
  alignas(64) uint32_t buf[RegisterTable::kMaxVecs * kMaxLanes] = {};
  for (uint32_t e = 0; e < n_entries; ++e) std::memcpy(&buf[e], lt + 2 * size_t(e), 4);
  for (int v = 0; v < RegisterTable::kMaxVecs; ++v) r.t[v] = hn::Load(du, buf + v * N);  // unused ones zero
  return r;
}

HWY_INLINE hn::Vec<DU> RegisterLookup(const RegisterTable& r, hn::Vec<DU> e) {
#if HWY_TARGET <= HWY_AVX3
  // Two-table permutes cover 32 entries each: at most two permutes and a blend.
  const __m512i lo = _mm512_permutex2var_epi32(r.t[0].raw, e.raw, r.t[1].raw);
  if (r.vecs <= 2) return hn::Vec<DU>{lo};
  const __m512i hi = _mm512_permutex2var_epi32(r.t[2].raw, e.raw, r.t[3].raw);
  return hn::Vec<DU>{_mm512_mask_blend_epi32(_mm512_test_epi32_mask(e.raw, _mm512_set1_epi32(32)), lo, hi)};
#else
  const DU du;
  const DI di;
  const size_t N = hn::Lanes(du);
  const auto lane = hn::IndicesFromVec(du, hn::And(e, hn::Set(du, uint32_t(N - 1))));
  auto v = hn::TableLookupLanes(r.t[0], lane);
  for (int k = 1; k < r.vecs; ++k)  // entries < 2^31: a signed compare
    v = hn::IfThenElse(hn::RebindMask(du, hn::Gt(hn::BitCast(di, e), hn::Set(di, int32_t(k * N) - 1))),
                       hn::TableLookupLanes(r.t[k], lane), v);
  return v;
#endif
}

// The four x-pairs of a block of N samples on a dense level, lanes = samples: pair j holds corners
// k = 2j (entry e) and 2j + 1 (entry e + 1, or entry 0 where e + 1 wraps), with the weights of
// CornersVec (same operations, so the same bits) and the same entries (u32 sums of the same terms).
struct PairBlock {
  hn::Vec<DU> e[4];
  hn::Mask<DU> wraps[4];  // e = n - 1: the x0 + 1 corner is entry 0
  hn::Vec<DF> wa[4], wb[4];
};

HWY_INLINE void DensePairs(const GridLevel& L, bool smooth, const float* x, const float* y, const float* z, size_t s0,
                           PairBlock& pb) {
  const DU du;
  hn::Vec<DU> i[3];
  hn::Vec<DF> sv[3], sm[3];
  LatticeCoords(L, smooth, x + s0, y + s0, z + s0, i, sv, sm);
  const auto res = hn::Set(du, L.res), res2 = hn::Set(du, L.res * L.res);
  const auto nent = hn::Set(du, L.n_entries), mask = hn::Set(du, L.pow2_mask), c1 = hn::Set(du, 1u);
  // Row offsets of y0, y0 + 1 and z0, z0 + 1 (u32 arithmetic: the same sums as CornersVec's products).
  const auto ry0 = hn::Mul(i[1], res), rz0 = hn::Mul(i[2], res2);
  const hn::Vec<DU> ry[2] = {ry0, hn::Add(ry0, res)}, rz[2] = {rz0, hn::Add(rz0, res2)};
  // (wx * wy) * wz in CornersVec's order; the wx * wy products are shared by both z.
  const hn::Vec<DF> ay[2] = {hn::Mul(sm[0], sm[1]), hn::Mul(sm[0], sv[1])}, by[2] = {hn::Mul(sv[0], sm[1]), hn::Mul(sv[0], sv[1])};
  for (int j = 0; j < 4; ++j) {
    auto e = hn::Add(hn::Add(i[0], ry[j & 1]), rz[j >> 1]);
    if (L.pow2_mask) e = hn::And(e, mask);
    else e = hn::Min(e, hn::Sub(e, nent));
    pb.e[j] = e;
    pb.wraps[j] = hn::Eq(hn::Add(e, c1), nent);  // both the modulo and the mask wrap n to 0
    const auto wz = (j & 2) ? sv[2] : sm[2];
    pb.wa[j] = hn::Mul(ay[j & 1], wz);
    pb.wb[j] = hn::Mul(by[j & 1], wz);
  }
}

// Forward, dense levels with two features, lanes = samples. An entry is 32 bits (feature 0 in the
// low half) and a pair's entries are adjacent, so a pair costs one 64-bit gather element
// (gathers cost per element on Zen 4) or, for a table that fits in registers, two permutes. Two
// 16-bit permutes de-interleave the features; the corners accumulate in the order k = 0..7, so the
// result is the per-sample path's bit for bit.
HWY_INLINE void DensePairBlockF2(const GridLevel& L, bool smooth, const uint16_t* lt, const RegisterTable& rt,
                                 const float* x, const float* y, const float* z, float* out, int n, size_t s0) {
  const DF df;
  const DU du;
  const DI di;
  const hn::Repartition<uint16_t, DF> du16;
  const hn::Half<decltype(du16)> du16h;
  const hn::Rebind<hwy::float16_t, DF> dh;
  const auto c1 = hn::Set(du, 1u);
  PairBlock pb;
  DensePairs(L, smooth, x, y, z, s0, pb);
  const float* base = reinterpret_cast<const float*>(lt);  // entries as 32-bit words: only moved, never computed on
  auto acc0 = hn::Zero(df), acc1 = hn::Zero(df);
  for (int j = 0; j < 4; ++j) {
    const auto e = pb.e[j];
    const auto wraps = pb.wraps[j];
    hn::Vec<decltype(du16)> f0, f1;  // [feature 0 of x0 | of x0 + 1], [feature 1 of x0 | of x0 + 1]
#if HWY_TARGET <= HWY_AVX3
    if (!rt.vecs && hn::AllFalse(du, wraps)) {
      // One gather per 8 samples, each 64-bit lane (f0 x0, f1 x0, f0 x1, f1 x1); one two-table
      // 16-bit permute per feature puts the 16 samples' x0 values low and x1 values high.
      const __m512i e32 = e.raw;
      const __m512i lo = _mm512_i32gather_epi64(_mm512_castsi512_si256(e32), base, 4);
      const __m512i hi = _mm512_i32gather_epi64(_mm512_extracti64x4_epi64(e32, 1), base, 4);
      alignas(64) static constexpr uint16_t kF0[32] = {0,  4,  8,  12, 16, 20, 24, 28, 32, 36, 40, 44, 48, 52, 56, 60,
                                                       2,  6,  10, 14, 18, 22, 26, 30, 34, 38, 42, 46, 50, 54, 58, 62};
      const __m512i sel0 = _mm512_load_si512(kF0), c1w = _mm512_set1_epi16(1);
      f0.raw = _mm512_permutex2var_epi16(lo, sel0, hi);
      f1.raw = _mm512_permutex2var_epi16(lo, _mm512_add_epi16(sel0, c1w), hi);
    } else
#endif
    {
      hn::Vec<DF> a, b;
      if (rt.vecs) {
        a = hn::BitCast(df, RegisterLookup(rt, e));
        b = hn::BitCast(df, RegisterLookup(rt, hn::IfThenZeroElse(wraps, hn::Add(e, c1))));
      } else {
        // A wrapping lane gathers the pair (n - 2, n - 1) instead, never reading past the table.
        hn::Vec<DF> p, q;
        vnr::HWY_NAMESPACE::GatherPairs(df, base, hn::BitCast(di, hn::IfThenElse(wraps, hn::Sub(e, c1), e)), &p, &q);
        a = hn::IfThenElse(hn::RebindMask(df, wraps), q, p);
        b = hn::IfThenElse(hn::RebindMask(df, wraps), hn::Set(df, base[0]), q);
      }
      f0 = hn::ConcatEven(du16, hn::BitCast(du16, b), hn::BitCast(du16, a));
      f1 = hn::ConcatOdd(du16, hn::BitCast(du16, b), hn::BitCast(du16, a));
    }
    const auto a0 = hn::PromoteTo(df, hn::BitCast(dh, hn::LowerHalf(du16h, f0)));
    const auto b0 = hn::PromoteTo(df, hn::BitCast(dh, hn::UpperHalf(du16h, f0)));
    const auto a1 = hn::PromoteTo(df, hn::BitCast(dh, hn::LowerHalf(du16h, f1)));
    const auto b1 = hn::PromoteTo(df, hn::BitCast(dh, hn::UpperHalf(du16h, f1)));
    acc0 = hn::MulAdd(pb.wb[j], b0, hn::MulAdd(pb.wa[j], a0, acc0));
    acc1 = hn::MulAdd(pb.wb[j], b1, hn::MulAdd(pb.wa[j], a1, acc1));
  }
  hn::StoreU(acc0, df, out + s0);
  hn::StoreU(acc1, df, out + size_t(n) + s0);
}

#endif

template <int F>
void EncodeF(const GridLayout& g, const uint16_t* table, const float* x, const float* y, const float* z, int n,
             float* X0) {
  const DF df;
  const size_t N = hn::Lanes(df);
  for (uint32_t l = 0; l < g.n_levels; ++l) {
    const GridLevel L = g.levels[l];
    float* out = X0 + size_t(l) * F * n;
    const bool vec_ok = VectorPathOk(L, g);
    const uint16_t* lt = table + uint64_t(L.offset) * F;
    // Levels whose table fits in L2 gain nothing from prefetching; bigger ones are latency-bound.
    const bool pf = uint64_t(L.n_entries) * F * sizeof(uint16_t) > (uint64_t(1) << 18);
    const int nb = ValidBlocks(vec_ok, x, y, z, n, N);
    const bool smooth = g.interpolation == Interpolation::Smoothstep;
#if HWY_TARGET != HWY_SCALAR
    if (F == 2 && !L.hashed && !pf && N >= 4) {
      const RegisterTable rt = LoadRegisterTable(lt, L.n_entries);
      for (int b = 0; b < nb; ++b) DensePairBlockF2(L, smooth, lt, rt, x, y, z, out, n, size_t(b) * N);
    } else
#endif
    {
      PipelinedBlocks<F>(L, smooth, x, y, z, nb, N, lt, pf,
                         [&](const CornerBlock& cur, size_t s0) { GatherBlock<F>(lt, cur, N, out, n, s0); });
    }
    for (int s = nb * int(N); s < n; ++s) grid_level_forward<F>(L, g.interpolation, table, x[s], y[s], z[s], out + s, n);
  }
}

// One exported entry per feature count (HWY_EXPORT takes plain names); GridEncoding<F> calls its own.
#define VNR_GRID_ENCODE(F)                                                                                       \
  void GridEncode##F(const GridLayout& g, const uint16_t* table, const float* x, const float* y, const float* z, \
                     int n, float* X0) {                                                                          \
    EncodeF<F>(g, table, x, y, z, n, X0);                                                                        \
  }
VNR_GRID_FEATURE_COUNTS(VNR_GRID_ENCODE)
#undef VNR_GRID_ENCODE

// Backward of one block of N samples from its corner block: per sample and corner, one vector load of
// the F gradients, one FMA, one store (grad = w * g + grad, the reference's fmaf per element).
template <int F>
HWY_INLINE void ScatterBlock(float* lg, const CornerBlock& cur, size_t N, const float* dy, int chunk, size_t s0) {
  const DFF<F> dff;
  constexpr size_t NV = (F + hn::MaxLanes(DFF<F>()) - 1) / hn::MaxLanes(DFF<F>());
  const size_t NF = hn::Lanes(dff);
  for (size_t s = 0; s < N; ++s) {
    alignas(64) float gtmp[NV * kMaxLanes];
    for (int f = 0; f < F; ++f) gtmp[f] = dy[f * chunk + s0 + s];
    hn::Vec<DFF<F>> gv[NV];
    for (size_t v = 0; v < NV; ++v) gv[v] = hn::LoadU(dff, gtmp + v * NF);
    for (int k = 0; k < 8; ++k) {
      float* gr = lg + uint64_t(cur.entry[k][s]) * F;
      const auto w = hn::Set(dff, cur.weight[k][s]);
      for (size_t v = 0; v < NV; ++v) hn::StoreU(hn::MulAdd(w, gv[v], hn::LoadU(dff, gr + v * NF)), dff, gr + v * NF);
    }
  }
}

#if HWY_TARGET <= HWY_AVX3
// Backward, dense levels with two features, 16 samples: the four gradients of a corner pair (f0, f1
// of x0, then of x0 + 1) are 16 adjacent bytes, so a pair is one 128-bit load, FMA and store instead
// of two of each, and the weights and gradients are put in per-sample quads by permutes rather than
// scalar loads (fewer instructions per sample). Same weights, entries and per-element FMA as
// ScatterBlock, in the same corner order, so the same bits. False (nothing done) when a lane's x0 + 1
// wraps to entry 0.
HWY_INLINE bool DensePairBlockBackwardF2(const GridLevel& L, bool smooth, const float* x, const float* y,
                                         const float* z, const float* dy, int chunk, size_t s0, float* lg) {
  const DU du;
  PairBlock pb;
  DensePairs(L, smooth, x, y, z, s0, pb);
  for (int j = 0; j < 4; ++j)
    if (!hn::AllFalse(du, pb.wraps[j])) return false;
  // kQuad[q]: lanes 4m..4m+3 = (a[4q+m], a[4q+m], b[4q+m], b[4q+m]) of a two-table permute (a, b).
  alignas(64) static constexpr uint32_t kQuad[4][16] = {
      {0, 0, 16, 16, 1, 1, 17, 17, 2, 2, 18, 18, 3, 3, 19, 19},
      {4, 4, 20, 20, 5, 5, 21, 21, 6, 6, 22, 22, 7, 7, 23, 23},
      {8, 8, 24, 24, 9, 9, 25, 25, 10, 10, 26, 26, 11, 11, 27, 27},
      {12, 12, 28, 28, 13, 13, 29, 29, 14, 14, 30, 30, 15, 15, 31, 31}};
  // The gradient quad is (g0, g1, g0, g1): kQuad with b's lanes swapped into the middle.
  alignas(64) static constexpr uint32_t kGrad[4][16] = {
      {0, 16, 0, 16, 1, 17, 1, 17, 2, 18, 2, 18, 3, 19, 3, 19},
      {4, 20, 4, 20, 5, 21, 5, 21, 6, 22, 6, 22, 7, 23, 7, 23},
      {8, 24, 8, 24, 9, 25, 9, 25, 10, 26, 10, 26, 11, 27, 11, 27},
      {12, 28, 12, 28, 13, 29, 13, 29, 14, 30, 14, 30, 15, 31, 15, 31}};
  alignas(64) float w4[4][64], g4[64];
  alignas(64) uint32_t e[4][16];
  const __m512 g0 = _mm512_loadu_ps(dy + s0), g1 = _mm512_loadu_ps(dy + size_t(chunk) + s0);
  for (int q = 0; q < 4; ++q)
    _mm512_store_ps(g4 + 16 * q, _mm512_permutex2var_ps(g0, _mm512_load_si512(kGrad[q]), g1));
  for (int j = 0; j < 4; ++j) {
    _mm512_store_si512(e[j], pb.e[j].raw);
    for (int q = 0; q < 4; ++q)
      _mm512_store_ps(w4[j] + 16 * q, _mm512_permutex2var_ps(pb.wa[j].raw, _mm512_load_si512(kQuad[q]), pb.wb[j].raw));
  }
  for (int s = 0; s < 16; ++s) {
    const __m128 g = _mm_load_ps(g4 + 4 * s);
    for (int j = 0; j < 4; ++j) {
      float* p = lg + 2 * size_t(e[j][s]);
      _mm_storeu_ps(p, _mm_fmadd_ps(_mm_load_ps(w4[j] + 4 * s), g, _mm_loadu_ps(p)));
    }
  }
  return true;
}
#endif

template <int F>
void BackwardF(const GridLayout& g, uint32_t l, const float* x, const float* y, const float* z, int64_t n,
               const float* dEnc, uint32_t in_pad, int chunk, float* grad) {
  const DF df;
  const int64_t N = int64_t(hn::Lanes(df));
  const GridLevel L = g.levels[l];
  const bool vec_ok = VectorPathOk(L, g) && chunk % N == 0;
  float* lg = grad + uint64_t(L.offset) * F;
  const bool pf = uint64_t(L.n_entries) * F * sizeof(float) > (uint64_t(1) << 18);
  const bool smooth = g.interpolation == Interpolation::Smoothstep;
  for (int64_t c0 = 0; c0 < n; c0 += chunk) {
    const float* dy = dEnc + (c0 / chunk) * int64_t(in_pad) * chunk + int64_t(l) * F * chunk;
    const int64_t m = n - c0 < chunk ? n - c0 : chunk;
    const int nb = ValidBlocks(vec_ok, x + c0, y + c0, z + c0, m, size_t(N));
    const float *xc = x + c0, *yc = y + c0, *zc = z + c0;
#if HWY_TARGET <= HWY_AVX3
    if (F == 2 && !L.hashed && !pf) {
      for (int b = 0; b < nb; ++b) {
        const size_t s0 = size_t(b) * size_t(N);
        if (DensePairBlockBackwardF2(L, smooth, xc, yc, zc, dy, chunk, s0, lg)) continue;
        CornerBlock cb;
        CornersVec(L, smooth, xc + s0, yc + s0, zc + s0, cb);
        ScatterBlock<F>(lg, cb, size_t(N), dy, chunk, s0);
      }
    } else
#endif
    {
      PipelinedBlocks<F>(L, smooth, xc, yc, zc, nb, size_t(N), lg, pf, [&](const CornerBlock& cur, size_t s0) {
        ScatterBlock<F>(lg, cur, size_t(N), dy, chunk, s0);
      });
    }
    for (int64_t s = int64_t(nb) * N; s < m; ++s)
      grid_level_backward<F>(L, g.interpolation, grad, x[c0 + s], y[c0 + s], z[c0 + s], dy + s, chunk);
  }
}

#define VNR_GRID_BACKWARD(F)                                                                                    \
  void GridBackwardLevel##F(const GridLayout& g, uint32_t level, const float* x, const float* y, const float* z, \
                            int64_t n, const float* dEnc, uint32_t in_pad, int chunk, float* grad) {            \
    BackwardF<F>(g, level, x, y, z, n, dEnc, in_pad, chunk, grad);                                              \
  }
VNR_GRID_FEATURE_COUNTS(VNR_GRID_BACKWARD)
#undef VNR_GRID_BACKWARD

// adam_update() (adam_update.h) vectorised: the zero-gradient skip of grid parameters is a per-lane
// select, bias corrections are gathered from tables indexed by the per-parameter step count. Every
// lane computes exactly adam_update's operations (no fused ones); tests/test_encodings.cpp checks the bits.
void AdamRange(const AdamStep& k, float* HWY_RESTRICT w, float* HWY_RESTRICT grads, float* HWY_RESTRICT m,
               float* HWY_RESTRICT v, uint32_t* HWY_RESTRICT c, uint16_t* HWY_RESTRICT half, int64_t n) {
  const hn::Rebind<hwy::float16_t, DF> dh;
  const DF df;
  const DI di;
  const int64_t N = int64_t(hn::Lanes(df));
  const auto zero = hn::Zero(df), one = hn::Set(df, 1.0f);
  const auto b1 = hn::Set(df, k.beta1), b2 = hn::Set(df, k.beta2);
  const auto nb1 = hn::Set(df, 1.0f - k.beta1), nb2 = hn::Set(df, 1.0f - k.beta2);
  const auto l2 = hn::Set(df, k.l2), lr = hn::Set(df, k.lr), eps = hn::Set(df, k.eps);
  const auto rel = hn::Set(df, k.rel), absd = hn::Set(df, k.abs_decay);
  const auto lo = hn::Set(df, k.lo), hi = hn::Set(df, k.hi);
  const auto ione = hn::Set(di, 1);
  int64_t i = 0;
  for (; i + N <= n; i += N) {
    auto g = hn::LoadU(df, grads + i);
    hn::StoreU(zero, df, grads + i);
    const auto wi = hn::LoadU(df, w + i);
    const auto active = k.matrix ? hn::Eq(zero, zero) : hn::Ne(g, zero);
    if (!k.matrix && hn::AllFalse(df, active)) continue;
    if (k.matrix) g = hn::Add(g, hn::Mul(l2, wi));
    const auto m0 = hn::LoadU(df, m + i), v0 = hn::LoadU(df, v + i);
    const auto c0 = hn::LoadU(di, reinterpret_cast<const int32_t*>(c + i));
    const auto mi = hn::Add(hn::Mul(b1, m0), hn::Mul(nb1, g));
    const auto vi = hn::Add(hn::Mul(b2, v0), hn::Mul(hn::Mul(nb2, g), g));
    const auto ci = hn::Add(c0, ione);
    const auto bs = hn::GatherIndex(df, k.bias_sqrt, ci);
    const auto bd = hn::GatherIndex(df, k.bias_den, ci);
    const auto lr_t = hn::Div(hn::Mul(lr, bs), bd);
    auto eff = hn::Div(lr_t, hn::Add(hn::Sqrt(vi), eps));
    eff = hn::Min(hn::Max(eff, lo), hi);
    const auto wd = hn::Sub(hn::Mul(hn::Sub(one, hn::Mul(rel, lr_t)), wi), hn::CopySign(hn::Mul(absd, lr_t), wi));
    const auto wn = hn::Sub(wd, hn::Mul(eff, mi));
    const auto wnew = hn::IfThenElse(active, wn, wi);
    hn::StoreU(wnew, df, w + i);
    if (half) hn::StoreU(hn::DemoteTo(dh, wnew), dh, reinterpret_cast<hwy::float16_t*>(half + i));
    hn::StoreU(hn::IfThenElse(active, mi, m0), df, m + i);
    hn::StoreU(hn::IfThenElse(active, vi, v0), df, v + i);
    hn::StoreU(hn::IfThenElse(hn::RebindMask(di, active), ci, c0), di, reinterpret_cast<int32_t*>(c + i));
  }
  for (; i < n; ++i) {  // tail: the shared scalar update
    const float g = grads[i];
    grads[i] = 0.0f;
    if (!k.matrix && g == 0.0f) continue;
    const uint32_t ci = ++c[i];
    adam_update(k, k.matrix, g, k.bias_sqrt[ci], k.bias_den[ci], w[i], m[i], v[i]);
    if (half) half[i] = float_to_half(w[i]);
  }
}

void DeinterleaveXyz(const float* HWY_RESTRICT xyz, int64_t n, float* HWY_RESTRICT x, float* HWY_RESTRICT y,
                     float* HWY_RESTRICT z) {
  const DF df;
  const int64_t N = int64_t(hn::Lanes(df));
  int64_t i = 0;
  for (; i + N <= n; i += N) {
    hn::Vec<DF> a, b, c;
    hn::LoadInterleaved3(df, xyz + 3 * i, a, b, c);
    hn::StoreU(a, df, x + i);
    hn::StoreU(b, df, y + i);
    hn::StoreU(c, df, z + i);
  }
  for (; i < n; ++i) x[i] = xyz[3 * i], y[i] = xyz[3 * i + 1], z[i] = xyz[3 * i + 2];
}

}  // namespace HWY_NAMESPACE
}  // namespace vnr::kernels
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace vnr::kernels {
HWY_EXPORT(AdamRange);
HWY_EXPORT(DeinterleaveXyz);

void deinterleave_xyz(const float* xyz, int64_t n, float* x, float* y, float* z) {
  HWY_DYNAMIC_DISPATCH(DeinterleaveXyz)(xyz, n, x, y, z);
}

#define VNR_GRID_ENTRIES(F)                                                                                          \
  HWY_EXPORT(GridEncode##F);                                                                                         \
  HWY_EXPORT(GridBackwardLevel##F);                                                                                  \
  template <>                                                                                                        \
  void grid_encode<F>(const GridLayout& g, const uint16_t* table, const float* x, const float* y, const float* z,   \
                      int n, float* X0) {                                                                            \
    HWY_DYNAMIC_DISPATCH(GridEncode##F)(g, table, x, y, z, n, X0);                                                   \
  }                                                                                                                  \
  template <>                                                                                                        \
  void grid_backward_level<F>(const GridLayout& g, uint32_t level, const float* x, const float* y, const float* z, \
                              int64_t n, const float* dEnc, uint32_t in_pad, int chunk, float* grad) {               \
    HWY_DYNAMIC_DISPATCH(GridBackwardLevel##F)(g, level, x, y, z, n, dEnc, in_pad, chunk, grad);                     \
  }
VNR_GRID_FEATURE_COUNTS(VNR_GRID_ENTRIES)
#undef VNR_GRID_ENTRIES

void adam_range(const AdamStep& k, float* params, float* grads, float* m, float* v, uint32_t* c, uint16_t* half,
                int64_t n) {
  HWY_DYNAMIC_DISPATCH(AdamRange)(k, params, grads, m, v, c, half, n);
}
}  // namespace vnr::kernels
#endif
