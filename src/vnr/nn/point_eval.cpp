// Single-point network evaluation (see point_eval.h). Compiled once per SIMD target (Highway
// foreach_target); the constructor picks the target's specialised eval function once.
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "vnr/nn/point_eval.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

#include <cmath>
#include <cstring>
#include <utility>
#include "vnr/nn/lattice-inl.h"
#include "vnr/nn/loss.h"
#include "vnr/nn/network.h"
#include "vnr/nn/point_eval.h"

HWY_BEFORE_NAMESPACE();
namespace vnr::point_eval {
namespace HWY_NAMESPACE {

namespace hn = hwy::HWY_NAMESPACE;
using DF = hn::ScalableTag<float>;
using DU = hn::RebindToUnsigned<DF>;
using DI = hn::RebindToSigned<DF>;
using VF = hn::Vec<DF>;
constexpr size_t kN = hn::MaxLanes(DF());  // x86 targets: fixed vector length

template <int F>
using DFF = hn::CappedTag<float, F>;  // the F features of one grid entry
template <int F>
using DHF = hn::Rebind<hwy::float16_t, DFF<F>>;

// Stack buffer sizes (floats). Grid encodings: at most 32 levels x 8 features; parameter-free ones
// are bounded by kMaxParameterFreeWidth (checked by the constructor against in_pad).
constexpr size_t kGridEncMax = kMaxGridLevels * 8;
constexpr size_t kFreeEncMax = kMaxParameterFreeWidth;
constexpr size_t kHMax = PointEvalData::kMaxWidth + 64;  // width padded to the panel width

// Calls fn(std::integral_constant<int, k>) for k = 0 .. n-1: a guaranteed unroll with a constant k
// (GCC does not honour "#pragma GCC unroll" on these loops at -O2, and a run-time corner index
// sends the lattice vectors through memory).
template <class Fn, int... K>
HWY_INLINE void UnrollImpl(Fn&& fn, std::integer_sequence<int, K...>) {
  (fn(std::integral_constant<int, K>()), ...);
}
template <int n, class Fn>
HWY_INLINE void Unroll(Fn&& fn) {
  UnrollImpl(fn, std::make_integer_sequence<int, n>());
}

// ---------------------------------------------------------------- encoding

// Lattice of one level-vector (lanes = levels l0 .. l0 + kN): the integer terms of the corner
// indices and the interpolation factors. Index terms are prepared so that a corner's index is
// X ^ Y ^ Z (hashed levels) or X + Y + Z (dense): Y = cy * m1, Z = cz * m2 with m1, m2 the hash
// primes or (res, res^2); the +1 corners add m1 / m2 (the same value modulo 2^32 as (c + 1) * m).
struct LevelLattice {
  hn::Vec<DU> xy_hash[4], xy_sum[4], z[2];  // [a + 2b]: corner x + a, y + b
  hn::Vec<DU> n, mask;                      // modulus; mask = n - 1 (power of two) or ~0
  hn::Mask<DU> hashed;
  VF wxy[4], wz[2];                         // weight factors: wxy[a + 2b] = wx_a * wy_b
};

HWY_INLINE void SetupLattice(const PointEvalData& d, uint32_t l0, const VF (&pin)[3], bool smooth, LevelLattice& t) {
  const DF df;
  const DU du;
  const VF scale = hn::Load(df, d.lvl_scale + l0);
  hn::Vec<DU> c[3];
  VF sv[3], sm[3];
  for (int a = 0; a < 3; ++a) vnr::HWY_NAMESPACE::LatticeAxis(df, scale, pin[a], smooth, &c[a], &sv[a], &sm[a]);
  const auto m1 = hn::Load(du, d.lvl_m1 + l0), m2 = hn::Load(du, d.lvl_m2 + l0);
  const hn::Vec<DU> x[2] = {c[0], hn::Add(c[0], hn::Set(du, 1u))};
  const auto y0 = hn::Mul(c[1], m1), z0 = hn::Mul(c[2], m2);
  const hn::Vec<DU> y[2] = {y0, hn::Add(y0, m1)};
  t.z[0] = z0;
  t.z[1] = hn::Add(z0, m2);
  Unroll<4>([&](auto kc) {
    constexpr int k = kc;
    t.xy_hash[k] = hn::Xor(x[k & 1], y[k >> 1]);
    t.xy_sum[k] = hn::Add(x[k & 1], y[k >> 1]);
    t.wxy[k] = hn::Mul(k & 1 ? sv[0] : sm[0], k & 2 ? sv[1] : sm[1]);
  });
  t.wz[0] = sm[2];
  t.wz[1] = sv[2];
  t.n = hn::Load(du, d.lvl_n + l0);
  t.mask = hn::Load(du, d.lvl_mask + l0);
  t.hashed = hn::Ne(hn::Load(du, d.lvl_hashed + l0), hn::Zero(du));
}

// Entry (within its level) of corner k: grid_entry(). Power-of-two n_l: the mask (then idx < n_l
// and the Min below keeps it); otherwise idx < 2 n_l and Min(idx, idx - n_l) (unsigned wrap) is the
// modulo.
HWY_INLINE hn::Vec<DU> CornerEntry(const LevelLattice& t, int k) {
  auto idx = hn::IfThenElse(t.hashed, hn::Xor(t.xy_hash[k & 3], t.z[k >> 2]), hn::Add(t.xy_sum[k & 3], t.z[k >> 2]));
  idx = hn::And(idx, t.mask);
  return hn::Min(idx, hn::Sub(idx, t.n));
}

// Weight of corner k: (wx * wy) * wz, the reference's product order.
HWY_INLINE VF CornerWeight(const LevelLattice& t, int k) { return hn::Mul(t.wxy[k & 3], t.wz[k >> 2]); }

// Grid encoding of one point into out[0, L*F) (out[l*F + f], the network's order). Corner entries
// and weights of all levels are computed with lanes = levels (exactly grid_corners()' arithmetic,
// so bit-identical), then each level accumulates its corners' fp16 features in corner order with
// FMA (grid_level_forward's order).
template <int F>
HWY_INLINE void EncodeGrid(const PointEvalData& d, float x, float y, float z, float* HWY_RESTRICT out) {
  const GridLayout& g = d.grid;
  const uint32_t L = g.n_levels;
  const uint16_t* HWY_RESTRICT table = d.table;
  // The lane path needs inputs in [0, 1] (dense indices then stay below 2 n_l) and a fused
  // multiply-add (else MulAdd rounds twice and would differ from the reference's fmaf).
  const bool inside = x >= 0.0f && x <= 1.0f && y >= 0.0f && y <= 1.0f && z >= 0.0f && z <= 1.0f;
  if (!HWY_NATIVE_FMA || !inside) {
    for (uint32_t l = 0; l < L; ++l) grid_level_forward<F>(g.levels[l], g.interpolation, table, x, y, z, out + l * F, 1);
    return;
  }
  const DF df;
  const VF pin[3] = {hn::Set(df, x), hn::Set(df, y), hn::Set(df, z)};
  const bool nearest = g.interpolation == Interpolation::Nearest;
  const bool smooth = g.interpolation == Interpolation::Smoothstep;
  const int kn = nearest ? 1 : 8;
  alignas(64) uint32_t ent[8][kMaxGridLevels];
  alignas(64) float wt[8][kMaxGridLevels];
  {
    const DU du;
    for (uint32_t l0 = 0; l0 < L; l0 += uint32_t(kN)) {  // kN divides kMaxGridLevels
      LevelLattice t;
      SetupLattice(d, l0, pin, smooth, t);
      if (nearest) {  // tcnn: the lower corner, weight 1
        hn::Store(CornerEntry(t, 0), du, ent[0] + l0);
        hn::Store(hn::Set(df, 1.0f), df, wt[0] + l0);
      } else {
        Unroll<8>([&](auto k) {
          hn::Store(CornerEntry(t, k), du, ent[k] + l0);
          hn::Store(CornerWeight(t, k), df, wt[k] + l0);
        });
      }
    }
  }
  // Start the cache misses of the large levels before any of them is needed: the loads below
  // then overlap instead of waiting in turn behind the reorder window. L2 hint, as the batched
  // encoder (more misses in flight than the L1 tracks).
  if (d.first_big < L) {
    for (uint32_t l = d.first_big; l < L; ++l)
      if (d.lvl_big[l])
        for (int k = 0; k < kn; ++k) __builtin_prefetch(d.lvl_ptr[l] + uint64_t(ent[k][l]) * F, 0, 2);
  }
  const DFF<F> dff;
  const DHF<F> dhf;
  constexpr size_t NF = hn::MaxLanes(DFF<F>());
  constexpr size_t NV = (F + NF - 1) / NF;
  for (uint32_t l = 0; l < L; ++l) {
    if (!d.lvl_vec[l]) {
      grid_level_forward<F>(g.levels[l], g.interpolation, table, x, y, z, out + l * F, 1);
      continue;
    }
    const uint16_t* HWY_RESTRICT lt = d.lvl_ptr[l];
    hn::Vec<DFF<F>> acc[NV];
    for (size_t v = 0; v < NV; ++v) acc[v] = hn::Zero(dff);
    auto corner = [&](int k) {  // one fp16 load, one conversion, one FMA per vector of features
      const auto* th = reinterpret_cast<const hwy::float16_t*>(lt + uint64_t(ent[k][l]) * F);
      const auto w = hn::Set(dff, wt[k][l]);
      for (size_t v = 0; v < NV; ++v) acc[v] = hn::MulAdd(w, hn::PromoteTo(dff, hn::LoadU(dhf, th + v * NF)), acc[v]);
    };
    if (nearest) corner(0);
    else Unroll<8>(corner);
    for (size_t v = 0; v < NV; ++v) hn::StoreU(acc[v], dff, out + l * F + v * NF);
  }
}

// Prefetch hint for a point evaluated soon: the corner lines of the large levels, into L2.
template <int F>
HWY_INLINE void PrefetchGrid(const PointEvalData& d, float x, float y, float z) {
  const bool inside = x >= 0.0f && x <= 1.0f && y >= 0.0f && y <= 1.0f && z >= 0.0f && z <= 1.0f;
  if (!HWY_NATIVE_FMA || !inside || d.first_big >= d.grid.n_levels) return;
  const DF df;
  const DU du;
  const VF pin[3] = {hn::Set(df, x), hn::Set(df, y), hn::Set(df, z)};
  const uint32_t L = d.grid.n_levels;
  const bool nearest = d.grid.interpolation == Interpolation::Nearest;
  const bool smooth = d.grid.interpolation == Interpolation::Smoothstep;
  alignas(64) uint32_t ent[8][kN];
  for (uint32_t l0 = d.first_big / uint32_t(kN) * uint32_t(kN); l0 < L; l0 += uint32_t(kN)) {
    LevelLattice t;
    SetupLattice(d, l0, pin, smooth, t);
    Unroll<8>([&](auto k) { hn::Store(CornerEntry(t, k), du, ent[k]); });
    const uint32_t le = L < l0 + uint32_t(kN) ? L : l0 + uint32_t(kN);
    for (uint32_t l = l0; l < le; ++l)
      if (d.lvl_big[l]) {
        const int kn = nearest ? 1 : 8;
        for (int k = 0; k < kn; ++k) __builtin_prefetch(d.lvl_ptr[l] + uint64_t(ent[k][l - l0]) * F, 0, 2);
      }
  }
}

// Parameter-free encodings: the network's own per-point encoder, padded with pad_value.
HWY_INLINE void EncodeFree(const PointEvalData& d, float x, float y, float z, float* HWY_RESTRICT out) {
  const float p[3] = {x, y, z};
  d.net->encode_point(p, out);
  for (uint32_t j = d.enc_width; j < d.in_pad; ++j) out[j] = d.pad_value;
}

template <int F>
HWY_INLINE void Encode(const PointEvalData& d, float x, float y, float z, float* HWY_RESTRICT out) {
  if constexpr (F == 0) EncodeFree(d, x, y, z, out);
  else EncodeGrid<F>(d, x, y, z, out);
}

// ---------------------------------------------------------------- MLP

// Accumulator sets: enough independent FMA chains (NV * S >= 8) to cover latency x throughput.
template <int NV>
constexpr int SetsFor() {
  return NV >= 8 ? 1 : 8 / NV;
}

// Adds the S accumulator sets into set 0 (pairwise). Spelled out per level: a loop the compiler
// does not unroll forces the accumulators through memory.
template <int S, int NV>
HWY_INLINE void ReduceSets(VF (&acc)[S][NV]) {
  static_assert(S == 1 || S == 2 || S == 4 || S == 8, "S must be a power of two <= 8");
  if constexpr (S >= 8) {
#pragma GCC unroll 16
    for (int v = 0; v < NV; ++v) {
      acc[0][v] = hn::Add(acc[0][v], acc[4][v]);
      acc[1][v] = hn::Add(acc[1][v], acc[5][v]);
      acc[2][v] = hn::Add(acc[2][v], acc[6][v]);
      acc[3][v] = hn::Add(acc[3][v], acc[7][v]);
    }
  }
  if constexpr (S >= 4) {
#pragma GCC unroll 16
    for (int v = 0; v < NV; ++v) {
      acc[0][v] = hn::Add(acc[0][v], acc[2][v]);
      acc[1][v] = hn::Add(acc[1][v], acc[3][v]);
    }
  }
  if constexpr (S >= 2) {
#pragma GCC unroll 16
    for (int v = 0; v < NV; ++v) acc[0][v] = hn::Add(acc[0][v], acc[1][v]);
  }
}

template <int NV>
HWY_INLINE void StorePanel(const VF (&y)[NV], bool relu, float* HWY_RESTRICT out) {
  const DF df;
#pragma GCC unroll 16
  for (int v = 0; v < NV; ++v) hn::Store(relu ? hn::Max(y[v], hn::Zero(df)) : y[v], df, out + v * kN);
}

// One panel of NV vectors of outputs: out = act(sum_j vals[j] * W[row_of(j) .. +PW]) over n inputs.
// Dense inputs use row_of(i) = i * PW; compacted ones (vals[j] = x[i_j] != 0) a table of i_j * PW.
// (`rows` is passed as a pointer: a caller's lambda that captured its row array by value would copy
// the array on every panel, in the innermost loop of in-shader inference.)
template <int NV, bool kDense>
HWY_INLINE void Panel(const float* HWY_RESTRICT W, const float* HWY_RESTRICT vals, const int32_t* HWY_RESTRICT rows,
                      uint32_t n, bool relu, float* HWY_RESTRICT out) {
  constexpr size_t PW = NV * kN;
  auto row_of = [rows](uint32_t j) { return kDense ? size_t(j) * PW : size_t(rows[j]); };
  constexpr int S = SetsFor<NV>();
  const DF df;
  VF acc[S][NV];
#pragma GCC unroll 16
  for (int s = 0; s < S; ++s)
#pragma GCC unroll 16
    for (int v = 0; v < NV; ++v) acc[s][v] = hn::Zero(df);
  uint32_t j = 0;
  for (; j + S <= n; j += S) {
#pragma GCC unroll 16
    for (int s = 0; s < S; ++s) {
      const VF xv = hn::Set(df, vals[j + s]);
      const float* HWY_RESTRICT row = W + row_of(j + s);
#pragma GCC unroll 16
      for (int v = 0; v < NV; ++v) acc[s][v] = hn::MulAdd(xv, hn::Load(df, row + v * kN), acc[s][v]);
    }
  }
  for (; j < n; ++j) {
    const VF xv = hn::Set(df, vals[j]);
    const float* HWY_RESTRICT row = W + row_of(j);
#pragma GCC unroll 16
    for (int v = 0; v < NV; ++v) acc[0][v] = hn::MulAdd(xv, hn::Load(df, row + v * kN), acc[0][v]);
  }
  ReduceSets(acc);
  StorePanel<NV>(acc[0], relu, out);
}

// Compacts the positive entries of h[0, n) (n a multiple of kN; ReLU outputs are >= 0) into
// vals / rows (row offsets i * PW). Register compress + plain store (memory-destination compress is
// microcoded on Zen 4). Returns the count; vals / rows need n + kN slots.
HWY_INLINE uint32_t CompactPositive(const float* HWY_RESTRICT h, uint32_t n, uint32_t PW, float* HWY_RESTRICT vals,
                                    int32_t* HWY_RESTRICT rows) {
  const DF df;
  const DI di;
  auto iota = hn::Mul(hn::Iota(di, 0), hn::Set(di, int32_t(PW)));
  const auto step = hn::Set(di, int32_t(kN * PW));
  const VF zero = hn::Zero(df);
  size_t cnt = 0;
  for (uint32_t j = 0; j < n; j += uint32_t(kN)) {
    const VF hv = hn::Load(df, h + j);
    const auto m = hn::Gt(hv, zero);
    hn::StoreU(hn::Compress(hv, m), df, vals + cnt);
    hn::StoreU(hn::Compress(iota, hn::RebindMask(di, m)), di, rows + cnt);
    cnt += hn::CountTrue(df, m);
    iota = hn::Add(iota, step);
  }
  return uint32_t(cnt);
}

// Forward pass from the (grid: unpadded, else padded) encoding x0; returns the first output after
// the output activation. Panel width PW = NV * kN (16, 32 or 64 floats).
template <int PW>
HWY_INLINE float MlpForward(const PointEvalData& d, const float* HWY_RESTRICT x0) {
  constexpr int NV = PW / int(kN) > 0 ? PW / int(kN) : 1;
  static_assert(NV * kN == size_t(PW), "panel width must be a multiple of the vector length");
  const DF df;
  alignas(64) float hbuf[2][kHMax];
  alignas(64) float vals[kHMax + kN];
  alignas(64) int32_t rows[kHMax + kN];
  const float* in = x0;
  uint32_t K = d.k0;
  const uint32_t np = d.n_panels;
  for (uint32_t k = 0; k < d.n_hidden; ++k) {
    float* HWY_RESTRICT h = hbuf[k & 1];
    const float* W = d.layer[k];
    const size_t panel_floats = size_t(K) * PW;
    if (k > 0 && d.skip_zeros) {
      const uint32_t nnz = CompactPositive(in, d.width_pad, PW, vals, rows);
      for (uint32_t p = 0; p < np; ++p)
        Panel<NV, false>(W + p * panel_floats, vals, rows, nnz, d.relu, h + p * PW);
    } else {
      for (uint32_t p = 0; p < np; ++p)
        Panel<NV, true>(W + p * panel_floats, in, nullptr, K, d.relu, h + p * PW);
    }
    // Outputs past the width (zero weights) are 0 after ReLU; keep them 0 without ReLU too (0 * inf).
    for (uint32_t o = d.width; o < d.width_pad; ++o) h[o] = 0.0f;
    in = h;
    K = d.width;
  }
  // Output row 0: a dot product over width_pad (zero-padded weights).
  VF a0 = hn::Zero(df), a1 = hn::Zero(df), a2 = hn::Zero(df), a3 = hn::Zero(df);
  const float* HWY_RESTRICT wo = d.wout;
  const uint32_t n = d.width_pad;
  uint32_t j = 0;
  for (; j + 4 * kN <= n; j += uint32_t(4 * kN)) {
    a0 = hn::MulAdd(hn::Load(df, wo + j), hn::Load(df, in + j), a0);
    a1 = hn::MulAdd(hn::Load(df, wo + j + kN), hn::Load(df, in + j + kN), a1);
    a2 = hn::MulAdd(hn::Load(df, wo + j + 2 * kN), hn::Load(df, in + j + 2 * kN), a2);
    a3 = hn::MulAdd(hn::Load(df, wo + j + 3 * kN), hn::Load(df, in + j + 3 * kN), a3);
  }
  for (; j < n; j += uint32_t(kN)) a0 = hn::MulAdd(hn::Load(df, wo + j), hn::Load(df, in + j), a0);
  const float y = hn::GetLane(hn::SumOfLanes(df, hn::Add(hn::Add(a0, a1), hn::Add(a2, a3))));
  return d.out_act == Activation::None ? y : activate(d.out_act, y);
}

// ---------------------------------------------------------------- entry points

template <int F, int PW>
HWY_NOINLINE float Eval(const PointEvalData& d, float x, float y, float z) {
  alignas(64) float enc[F == 0 ? kFreeEncMax : kGridEncMax];
  Encode<F>(d, x, y, z, enc);
  return MlpForward<PW>(d, enc);
}

template <int F>
HWY_NOINLINE void EncodeOnly(const PointEvalData& d, float x, float y, float z, float* out) {
  Encode<F>(d, x, y, z, out);
  if constexpr (F != 0)
    for (uint32_t j = d.enc_width; j < d.in_pad; ++j) out[j] = d.pad_value;
}

template <int PW>
HWY_NOINLINE float MlpOnly(const PointEvalData& d, const float* enc) {
  return MlpForward<PW>(d, enc);
}

template <int F>
HWY_NOINLINE void Prefetch(const PointEvalData& d, float x, float y, float z) {
  if constexpr (F != 0) PrefetchGrid<F>(d, x, y, z);
}

template <int F>
void PickKernels(const PointEvalData& d, PointEvalKernels* k) {
  k->encode = &EncodeOnly<F>;
  k->prefetch = &Prefetch<F>;
  switch (d.panel) {
    case 16: k->eval = &Eval<F, 16>; k->mlp = &MlpOnly<16>; break;
    case 32: k->eval = &Eval<F, 32>; k->mlp = &MlpOnly<32>; break;
    default: k->eval = &Eval<F, 64>; k->mlp = &MlpOnly<64>; break;
  }
}

// One exported entry per feature count (HWY_EXPORT takes plain names).
#define VNR_SELECT_KERNELS(F)                                       \
  void SelectKernels##F(const PointEvalData& d, PointEvalKernels* k) { \
    PickKernels<F>(d, k);                                           \
    k->target = hwy::TargetName(HWY_TARGET);                        \
  }
VNR_SELECT_KERNELS(0)  // no grid
VNR_GRID_FEATURE_COUNTS(VNR_SELECT_KERNELS)
#undef VNR_SELECT_KERNELS

}  // namespace HWY_NAMESPACE
}  // namespace vnr::point_eval
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
#include "vnr/error.h"
#include "vnr/nn/mlp_bf16.h"

namespace vnr {
namespace point_eval {
#define VNR_EXPORT_SELECT_KERNELS(F) HWY_EXPORT(SelectKernels##F);
VNR_EXPORT_SELECT_KERNELS(0)
VNR_GRID_FEATURE_COUNTS(VNR_EXPORT_SELECT_KERNELS)
#undef VNR_EXPORT_SELECT_KERNELS
}  // namespace point_eval

#define VNR_SELECT_KERNELS(F)                                                 \
  template <>                                                                 \
  void select_point_kernels<F>(const PointEvalData& d, PointEvalKernels* k) { \
    HWY_DYNAMIC_DISPATCH(point_eval::SelectKernels##F)(d, k);                 \
  }
VNR_SELECT_KERNELS(0)  // no grid
VNR_GRID_FEATURE_COUNTS(VNR_SELECT_KERNELS)
#undef VNR_SELECT_KERNELS

namespace {

// Inputs of hidden layer k: the encoding's columns for the first, the width after.
uint32_t K_of(const MlpLayout& m, uint32_t k) { return k == 0 ? m.first_cols : m.width; }

// The grid's per-level constants, padded to kMaxGridLevels with inert levels.
void fill_grid_levels(const Network& net, PointEvalData& d) {
  d.table = net.grid_half();
  d.grid = net.grid();
  const GridLayout& g = d.grid;
  const uint32_t F = g.n_features;
  for (uint32_t l = 0; l < uint32_t(kMaxGridLevels); ++l) {
    const bool real = l < g.n_levels;
    const GridLevel L = real ? g.levels[l] : GridLevel{0.0f, 1, 8, 0, 0, 7};
    d.lvl_scale[l] = L.scale;
    d.lvl_m1[l] = L.hashed ? 2654435761u : L.res;
    d.lvl_m2[l] = L.hashed ? 805459861u : L.res * L.res;
    d.lvl_n[l] = L.n_entries;
    d.lvl_mask[l] = L.pow2_mask ? L.pow2_mask : ~0u;
    d.lvl_hashed[l] = L.hashed;
    d.lvl_offset[l] = L.offset;
    d.lvl_ptr[l] = d.table + uint64_t(L.offset) * F;
    // Dense indices of inputs in [0, 1] stay below 2 n_l when n_l >= res^3 (not tiled).
    d.lvl_vec[l] = (L.hashed || L.pow2_mask || uint64_t(L.n_entries) >= uint64_t(L.res) * L.res * L.res) ? 1 : 0;
    d.lvl_big[l] = real && uint64_t(L.n_entries) * F * sizeof(uint16_t) > (uint64_t(1) << 18);
    if (d.lvl_big[l] && d.first_big == kMaxGridLevels) d.first_big = l;
}
if (g.n_levels * F > kMaxGridLevels * 8) fail("PointEvaluator: grid encoding too wide");
}

// Weights: per hidden layer, n_panels blocks of K rows x panel floats (row i = input i), then the
// first output row padded to width_pad. *finite says whether every weight is finite.
hwy::AlignedFreeUniquePtr<float[]> pack_fp32_panels(const Network& net, PointEvalData& d, bool* finite) {
  const MlpLayout& m = net.mlp();
  size_t total = 0;
  for (uint32_t k = 0; k < m.n_hidden; ++k) total += size_t(d.n_panels) * K_of(m, k) * d.panel;
  total += d.width_pad;
  auto weights = hwy::AllocateAligned<float>(total);
  float* w = weights.get();
  const float* P = net.params().data();
  for (uint32_t k = 0; k < m.n_hidden; ++k) {
    d.layer[k] = w;
    const uint32_t K = K_of(m, k);
    const uint64_t cols = m.cols[k];
    const float* W = P + m.offset[k];
    for (uint32_t p = 0; p < d.n_panels; ++p)
      for (uint32_t i = 0; i < K; ++i)
        for (uint32_t o = 0; o < d.panel; ++o) {
          const uint32_t r = p * d.panel + o;
          const float v = r < m.width ? W[r * cols + i] : 0.0f;
          *finite = *finite && std::isfinite(v);
          *w++ = v;
        }
  }
  d.wout = w;
  const float* Wo = P + m.offset[m.n_hidden];  // row 0 of the output matrix
  for (uint32_t c = 0; c < d.width_pad; ++c) {
    const float v = c < m.width ? Wo[c] : 0.0f;
    *finite = *finite && std::isfinite(v);
    *w++ = v;
  }
  return weights;
}

// The fp32 panels as bf16 pair panels: row j of a panel holds, per output o, the pair
// (W[o][2j], W[o][2j + 1]) (zero past K: an odd K's last pair).
hwy::AlignedFreeUniquePtr<uint32_t[]> pack_bf16_panels(const MlpLayout& m, PointEvalData& d) {
  size_t words = d.width_pad / 2;
  for (uint32_t k = 0; k < m.n_hidden; ++k) words += size_t(d.n_panels) * ((K_of(m, k) + 1) / 2) * d.panel;
  auto weights = hwy::AllocateAligned<uint32_t>(words);
  uint32_t* wb = weights.get();
  for (uint32_t k = 0; k < m.n_hidden; ++k) {
    d.layer_bf16[k] = wb;
    const uint32_t K = K_of(m, k);
    for (uint32_t p = 0; p < d.n_panels; ++p) {
      const float* F = d.layer[k] + size_t(p) * K * d.panel;  // fp32 panel p: row i = input i
      for (uint32_t j = 0; j < (K + 1) / 2; ++j)
        for (uint32_t o = 0; o < d.panel; ++o)
          *wb++ = kernels::bf16_pair(F[2 * j * d.panel + o], 2 * j + 1 < K ? F[(2 * j + 1) * d.panel + o] : 0.0f);
    }
  }
  d.wout_bf16 = wb;
  for (uint32_t c = 0; c < d.width_pad; c += 2) *wb++ = kernels::bf16_pair(d.wout[c], d.wout[c + 1]);
  return weights;
}

}  // namespace

PointEvaluator::PointEvaluator(const Network& net, bool skip_zero_activations) {
  const MlpLayout& m = net.mlp();
  PointEvalData& d = d_;
  d.net = &net;
  d.has_grid = net.has_grid();
  if (m.width > PointEvalData::kMaxWidth) fail("PointEvaluator: width {} exceeds {}", m.width, PointEvalData::kMaxWidth);
  if (m.n_hidden < 1 || m.n_hidden > 33) fail("PointEvaluator: unsupported n_hidden {}", m.n_hidden);
  if (d.has_grid) {
    fill_grid_levels(net, d);
  } else if (m.in_pad > kMaxParameterFreeWidth) {
    fail("PointEvaluator: encoding width {} exceeds {}", m.in_pad, kMaxParameterFreeWidth);
  }
  d.k0 = m.first_cols;
  d.in_pad = m.in_pad;
  d.enc_width = m.enc_width;
  d.pad_value = m.pad_value;
  d.width = m.width;
  d.n_hidden = m.n_hidden;
  d.relu = m.activation == Activation::ReLU;
  d.out_act = m.output_activation;
  d.panel = m.width <= 16 ? 16 : (m.width <= 32 ? 32 : 64);
  d.n_panels = (m.width + d.panel - 1) / d.panel;
  d.width_pad = d.n_panels * d.panel;

  bool finite = true;
  weights_ = pack_fp32_panels(net, d, &finite);
  // Compaction pays from 64 neurons on: at 16 and 32 the per-layer compaction and the
  // data-dependent loop cost more than the skipped FMAs.
  d.skip_zeros = skip_zero_activations && d.relu && finite && m.width > 32;

  PointEvalKernels k;
  net.encoding().select_point_kernels(d, &k);  // for the grid's F, fixed by the encoding factory
  eval_ = k.eval;
  encode_ = k.encode;
  mlp_ = k.mlp;
  prefetch_ = k.prefetch;
  target_ = k.target;
  if (net.inference_precision() == Precision::BF16 && point_eval::bf16_eval(d.panel)) {
    weights_bf16_ = pack_bf16_panels(m, d);
    d.encode = k.encode;
    d.skip_zeros = false;
    eval_ = point_eval::bf16_eval(d.panel);
    mlp_ = point_eval::bf16_mlp(d.panel);
    precision_ = Precision::BF16;
  }
}

}  // namespace vnr
#endif  // HWY_ONCE
