// Packet ray marching of the grid and of the brick cache (see grid_packets.h), compiled per SIMD target.
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "vnr/fields/grid_packets.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

#include <cmath>
#include <cstring>
#include <vector>
#include "vnr/render/brick_cache_view.h"
#include "vnr/fields/fields.h"
#include "vnr/fields/grid_packets.h"
#include "vnr/volume/lookup-inl.h"

HWY_BEFORE_NAMESPACE();
namespace vnr {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

namespace {
constexpr int kPacketsInFlight = 2;
template <class D, class M>
HWY_INLINE uint64_t lane_bits(D d, M m) {
  uint8_t bytes[8] = {};
  hn::StoreMaskBits(d, m, bytes);
  uint64_t b;
  std::memcpy(&b, bytes, 8);
  return b;
}

// unit_pow (render/integrators.h) on vectors: the same operations in the same order, bit for bit.
template <class DF, class VF = hn::Vec<DF>>
HWY_INLINE VF UnitPowVec(DF df, VF b, VF e) {
  const hn::RebindToSigned<DF> di;
  const auto c = [&](float v) { return hn::Set(df, v); };
  const auto bits = hn::BitCast(di, b);
  auto k = hn::Sub(hn::ShiftRight<23>(bits), hn::Set(di, 127));
  VF m = hn::BitCast(df, hn::Or(hn::And(bits, hn::Set(di, 0x7fffff)), hn::Set(di, 0x3f800000)));
  const auto big = hn::Gt(m, c(kUnitPowSqrt2));
  m = hn::IfThenElse(big, hn::Mul(m, c(0.5f)), m);
  k = hn::IfThenElse(hn::RebindMask(di, big), hn::Add(k, hn::Set(di, 1)), k);
  const VF t = hn::Div(hn::Sub(m, c(1.0f)), hn::Add(m, c(1.0f))), t2 = hn::Mul(t, t);
  const auto mul_add = [&](VF x, float a, float b0) { return hn::Add(hn::Mul(c(a), x), c(b0)); };  // a x + b0
  const VF series = hn::Add(mul_add(t2, kAtanh3, 1.0f),
                            hn::Mul(hn::Mul(t2, t2), hn::Add(hn::Mul(mul_add(t2, kAtanh9, kAtanh7), t2), c(kAtanh5))));
  const VF y = hn::Mul(e, hn::Add(hn::ConvertTo(df, k), hn::Mul(hn::Mul(t, series), c(kLog2Atanh))));
  const VF n = hn::Round(y), f = hn::Sub(y, n), f2 = hn::Mul(f, f);
  const VF low = hn::Add(mul_add(f, kExp2C2, kExp2C1), hn::Mul(f2, mul_add(f, kExp2C4, kExp2C3)));
  const VF q = hn::Add(c(1.0f), hn::Mul(f, hn::Add(low, hn::Mul(hn::Mul(f2, f2), mul_add(f, kExp2C6, kExp2C5)))));
  const VF scale = hn::BitCast(df, hn::ShiftLeft<23>(hn::Add(hn::ConvertTo(di, n), hn::Set(di, 127))));
  const VF general = hn::IfThenElseZero(hn::Ge(y, c(-126.0f)), hn::Mul(q, scale));
  return hn::IfThenElseZero(hn::Gt(b, hn::Zero(df)), hn::IfThenElse(hn::Eq(e, c(2.0f)), hn::Mul(b, b), general));
}
}  // namespace

// One packet of rays: the vector part of the lane state in structure-of-arrays form, the scalar DDA
// state per lane.
struct RayPacket {
  static constexpr size_t kMaxLanes = HWY_MAX_BYTES / sizeof(float);
  alignas(HWY_MAX_BYTES) float t[kMaxLanes] = {}, seg_end[kMaxLanes] = {}, seg_len[kMaxLanes] = {},
                               jit[kMaxLanes] = {}, ox[kMaxLanes] = {}, oy[kMaxLanes] = {}, oz[kMaxLanes] = {},
                               dx[kMaxLanes] = {}, dy[kMaxLanes] = {}, dz[kMaxLanes] = {}, ar[kMaxLanes] = {},
                               ag[kMaxLanes] = {}, ab[kMaxLanes] = {}, aw[kMaxLanes] = {};
  StepState st[kMaxLanes];
  int64_t pix[kMaxLanes] = {};
  uint64_t active = 0;
};

// The grid's lanes: GridLookupVec, with the next sample's rows prefetched.
struct GridLanes {
  const GridView& g;
  template <class DF, class VF>
  HWY_INLINE void prefetch(DF df, VF ux, VF uy, VF uz) const {
    GridPrefetchVec(df, g, ux, uy, uz);
  }
  template <class DF, class VF>
  HWY_INLINE VF lookup(DF df, VF ux, VF uy, VF uz, uint64_t) {
    return GridLookupVec<true>(df, g, ux, uy, uz);
  }
};

// The brick cache's lanes: BrickCacheView::sample for a vector of points, bit for bit. The lanes of
// each level (one, or more where the packet straddles a boundary, or blends two levels) read their
// decoded bricks with GridLookupVec's arithmetic (x-neighbours as pairs); misses take the scalar path
// (the whole sample: its levels, then the source).
struct CacheLanes {
  static constexpr size_t kMaxLanes = HWY_MAX_BYTES / sizeof(float);
  const BrickCacheView& c;
  const RenderableField& source;
  alignas(HWY_MAX_BYTES) int32_t last_brick[kMaxLanes] = {};
  int last_level = -1;

  // GridPrefetchVec's rows in the pool, at the level the last lookup read (most samples stay in it);
  // bricks not in are skipped.
  template <class DF, class VF>
  HWY_INLINE void prefetch(DF df, VF ux, VF uy, VF uz) const {
    if (last_level < 0) return;
    const hn::RebindToSigned<DF> di;
    const CacheLevelView& L = c.level[last_level];
    const int s = c.shift;
    const auto x = hn::ConvertTo(di, CellAxisPos(df, ux, L.nx)), y = hn::ConvertTo(di, CellAxisPos(df, uy, L.ny)),
               z = hn::ConvertTo(di, CellAxisPos(df, uz, L.nz));
    const auto bx = hn::ShiftRightSame(x, s), by = hn::ShiftRightSame(y, s), bz = hn::ShiftRightSame(z, s);
    const auto slot = hn::GatherIndex(di, L.slot, hn::Add(bx, hn::Mul(hn::Set(di, L.bx), hn::Add(by, hn::Mul(hn::Set(di, L.by), bz)))));
    // at_level's offsets in the pool (32-bit, as there)
    const auto off = hn::Add(hn::Mul(slot, hn::Set(di, int32_t(c.brick_floats))),
                             hn::Add(hn::Sub(x, hn::ShiftLeftSame(bx, s)),
                                     hn::Add(hn::Mul(hn::Sub(y, hn::ShiftLeftSame(by, s)), hn::Set(di, c.sy)),
                                             hn::Mul(hn::Sub(z, hn::ShiftLeftSame(bz, s)), hn::Set(di, c.sz)))));
    alignas(HWY_MAX_BYTES) int32_t offs[kMaxLanes];
    hn::Store(off, di, offs);
    for (uint64_t in = lane_bits(df, hn::RebindMask(df, hn::Gt(slot, hn::Set(di, -1)))); in; in &= in - 1) {
      const float* p0 = c.pool + offs[__builtin_ctzll(in)];  // bricks not in are skipped
      __builtin_prefetch(p0, 0, 2);
      __builtin_prefetch(p0 + c.sy, 0, 2);
      __builtin_prefetch(p0 + c.sz, 0, 2);
      __builtin_prefetch(p0 + c.sy + c.sz, 0, 2);
    }
  }

  template <class DF, class VF>
  HWY_NOINLINE VF scalar(DF df, VF ux, VF uy, VF uz, uint64_t lanes, VF done) {
    alignas(HWY_MAX_BYTES) float x[kMaxLanes], y[kMaxLanes], z[kMaxLanes], v[kMaxLanes];
    hn::Store(ux, df, x), hn::Store(uy, df, y), hn::Store(uz, df, z), hn::Store(done, df, v);
    for (; lanes; lanes &= lanes - 1) {
      const size_t l = size_t(__builtin_ctzll(lanes));
      bool miss = false;
      v[l] = c.sample(x[l], y[l], z[l], &miss);
      if (miss) v[l] = source.point(x[l], y[l], z[l]);
    }
    last_level = -1;
    return hn::Load(df, v);
  }

  template <class DF, class VF>
  HWY_INLINE VF lookup(DF df, VF ux, VF uy, VF uz, uint64_t active) {
    const hn::RebindToSigned<DF> di;
    uint64_t missed = 0;
    if (c.level0_only) {  // the view needs no level of detail per sample
      const VF value = at_level(df, 0, ux, uy, uz, active, &missed);
      return missed ? scalar(df, ux, uy, uz, missed, value) : value;
    }
    VF t;
    const auto lev = lane_levels(df, ux, uy, uz, &t);
    VF value = from_levels(df, lev, ux, uy, uz, active, &missed);
    const auto blends = hn::Gt(t, hn::Zero(df));
    if (const uint64_t blend = lane_bits(df, blends) & active & ~missed) {  // this + (coarser - this) * t
      const VF coarse = from_levels(df, hn::Add(lev, hn::Set(di, 1)), ux, uy, uz, blend, &missed);
      value = hn::IfThenElse(blends, hn::Add(value, hn::Mul(hn::Sub(coarse, value), t)), value);
    }
    return missed ? scalar(df, ux, uy, uz, missed, value) : value;
  }

  // The lanes of one level at a time (lev per lane); *missed gains the lanes whose brick is not in.
  template <class DF, class VF, class VI>
  HWY_INLINE VF from_levels(DF df, VI lev, VF ux, VF uy, VF uz, uint64_t active, uint64_t* missed) {
    const hn::RebindToSigned<DF> di;
    VF value = hn::Zero(df);
    for (uint64_t left = active; left;) {
      const int l = hn::ExtractLane(lev, size_t(__builtin_ctzll(left)));
      const auto at_l = hn::RebindMask(df, hn::Eq(lev, hn::Set(di, l)));
      const uint64_t lanes = lane_bits(df, at_l) & left;
      const VF v = at_level(df, l, ux, uy, uz, lanes, missed);
      value = lanes == active ? v : hn::IfThenElse(at_l, v, value);
      left &= ~lanes;
    }
    return value;
  }

  // The level each lane reads and its blend weight t (BrickCacheView::level_at, the same arithmetic).
  template <class DF, class VF>
  HWY_INLINE hn::Vec<hn::RebindToSigned<DF>> lane_levels(DF df, VF ux, VF uy, VF uz, VF* t) const {
    const hn::RebindToSigned<DF> di;
    using VI = hn::Vec<decltype(di)>;
    const VF dx = hn::Sub(hn::Mul(ux, hn::Set(df, c.box[0])), hn::Set(df, c.eye[0]));
    const VF dy = hn::Sub(hn::Mul(uy, hn::Set(df, c.box[1])), hn::Set(df, c.eye[1]));
    const VF dz = hn::Sub(hn::Mul(uz, hn::Set(df, c.box[2])), hn::Set(df, c.eye[2]));
    const VF m = hn::Mul(hn::Sqrt(hn::Add(hn::Add(hn::Mul(dx, dx), hn::Mul(dy, dy)), hn::Mul(dz, dz))),
                         hn::Set(df, c.lod_scale));
    const VI bits = hn::BitCast(di, m);
    const VI e = hn::Sub(hn::ShiftRight<23>(bits), hn::Set(di, 127));
    const VI top = hn::Set(di, c.levels - 1);
    const VF mant = hn::BitCast(df, hn::Or(hn::And(bits, hn::Set(di, 0x7fffff)), hn::Set(di, 0x3f800000)));
    const auto inner = hn::RebindMask(df, hn::And(hn::Gt(e, hn::Set(di, -1)), hn::Lt(e, top)));
    *t = hn::IfThenElse(hn::And(inner, hn::Ge(mant, hn::Set(df, kLodBlendStart))),
                        hn::Mul(hn::Sub(mant, hn::Set(df, kLodBlendStart)), hn::Set(df, kLodBlendInverse)), hn::Zero(df));
    return hn::Min(hn::Max(e, hn::Zero(di)), top);
  }

  template <class DF, class VF>
  HWY_INLINE VF at_level(DF df, int l, VF ux, VF uy, VF uz, uint64_t active, uint64_t* missed) {
    const hn::RebindToSigned<DF> di;
    using VI = hn::Vec<decltype(di)>;
    const int s = c.shift;
    const CacheLevelView& L = c.level[l];
    const hn::Vec<DF> u[3] = {ux, uy, uz};
    const int32_t n[3] = {L.nx, L.ny, L.nz};
    VI i0[3], i1[3];
    hn::Vec<DF> t[3];
    CellAxesVec<true>(df, u, n, i0, i1, t);  // x as pairs: GridLookupVec's kPairs
    const VI bx = hn::ShiftRightSame(i0[0], s), by = hn::ShiftRightSame(i0[1], s), bz = hn::ShiftRightSame(i0[2], s);
    const VI brick = hn::Add(bx, hn::Mul(hn::Set(di, L.bx), hn::Add(by, hn::Mul(hn::Set(di, L.by), bz))));
    const VI slot = hn::GatherIndex(di, L.slot, brick);
    const uint64_t miss = lane_bits(df, hn::RebindMask(df, hn::Lt(slot, hn::Zero(di)))) & active;
    // Bricks a lane enters are marked read this frame (the least-recently-used order of eviction).
    const VI last = hn::Load(di, last_brick);
    uint64_t entered = l == last_level ? lane_bits(df, hn::RebindMask(df, hn::Ne(brick, last))) & active & ~miss
                                       : active & ~miss;
    if (entered) {
      alignas(HWY_MAX_BYTES) int32_t bs[kMaxLanes];
      hn::Store(brick, di, bs);
      for (; entered; entered &= entered - 1) c.touch(l, bs[__builtin_ctzll(entered)]);
    }
    hn::Store(brick, di, last_brick);
    last_level = l;
    const VI sy = hn::Set(di, c.sy), sz = hn::Set(di, c.sz);
    const VI base = hn::Add(hn::Mul(hn::Max(slot, hn::Zero(di)), hn::Set(di, int32_t(c.brick_floats))),
                            hn::Add(hn::Sub(i0[0], hn::ShiftLeftSame(bx, s)),
                                    hn::Add(hn::Mul(hn::Sub(i0[1], hn::ShiftLeftSame(by, s)), sy),
                                            hn::Mul(hn::Sub(i0[2], hn::ShiftLeftSame(bz, s)), sz))));
    const VI dy = hn::Mul(hn::Sub(i1[1], i0[1]), sy), dz = hn::Mul(hn::Sub(i1[2], i0[2]), sz);
    hn::Vec<DF> v[8];
    for (int k = 0; k < 4; ++k) {
      const VI row = hn::Add(base, hn::Add(k & 1 ? dy : hn::Zero(di), k & 2 ? dz : hn::Zero(di)));
      GatherPairs(df, c.pool, row, &v[2 * k], &v[2 * k + 1]);
    }
    *missed |= miss;
    return TrilinearCornersVec(df, v, t);
  }
};

// Long on purpose: the hot SIMD loop keeps every lane's state in registers; split into calls it would spill.
template <class Lanes>
int64_t MarchPackets(const RenderParams& p, Lanes& lanes, TileCursor cursor, Vec4f* pixels) {
  const hn::ScalableTag<float> df;
  const hn::RebindToSigned<decltype(df)> di;
  using VF = hn::Vec<decltype(df)>;
  const size_t L = hn::Lanes(df);
  const int W = cursor.width;

  // Puts the next ray that enters a non-empty cell into lane l (rays that do not are written at
  // once); false when the cursor has no pixels left.
  auto start = [&](RayPacket& r, size_t l) {
    int ix, iy;
    while (cursor.next(&ix, &iy)) {
      const int64_t i = int64_t(iy) * W + ix;
      MarchState s;
      if (march_begin(p, ix, iy, s) && step_segment(p, s.st, true, p.step)) {
        r.st[l] = s.st;
        r.pix[l] = i;
        r.t[l] = s.st.t, r.seg_end[l] = s.st.seg_end, r.seg_len[l] = s.st.seg_len, r.jit[l] = s.st.jitter;
        r.ox[l] = s.st.org.x, r.oy[l] = s.st.org.y, r.oz[l] = s.st.org.z;
        r.dx[l] = s.st.dir.x, r.dy[l] = s.st.dir.y, r.dz[l] = s.st.dir.z;
        r.ar[l] = r.ag[l] = r.ab[l] = r.aw[l] = 0;
        return true;
      }
      pixels[i] = march_pixel(p, s);
    }
    return false;
  };
  // Writes lane l's pixel and refills the lane (or retires it).
  auto finish = [&](RayPacket& r, size_t l) {
    MarchState s;
    s.acc = Vec4f{r.ar[l], r.ag[l], r.ab[l], r.aw[l]};
    pixels[r.pix[l]] = march_pixel(p, s);
    if (!start(r, l)) r.active &= ~(uint64_t(1) << l);
  };

  // The table by channel, so that the two entries a lookup blends are neighbours (GatherPairs).
  std::vector<float> tf_soa(size_t(p.tf.n) * 4);
  for (int e = 0; e < p.tf.n; ++e) {
    const Vec4f c = p.tf.table[e];
    tf_soa[size_t(e)] = c.x, tf_soa[size_t(p.tf.n + e)] = c.y, tf_soa[size_t(2 * p.tf.n + e)] = c.z;
    tf_soa[size_t(3 * p.tf.n + e)] = c.w;
  }
  const auto zero = hn::Zero(df), one = hn::Set(df, 1.0f);
  const auto eps = hn::Set(df, step_eps(p.step));  // step_segment's, with march_next's fixed step
  const auto ibx = hn::Set(df, p.inv_box.x), iby = hn::Set(df, p.inv_box.y), ibz = hn::Set(df, p.inv_box.z);
  const auto tf_lo = hn::Set(df, p.tf.lo), tf_scale = hn::Set(df, p.tf.scale);
  const auto tf_last = hn::Set(df, float(p.tf.n - 1));
  const auto tf_imax = hn::Set(di, p.tf.n - 2);
  const auto alpha_stop = hn::Set(df, p.alpha_stop);
  int64_t samples = 0;

  // Lanes whose cell is used up get the next non-empty one (scalar DDA); rays that leave end.
  auto refresh = [&](RayPacket& r) {
    for (uint64_t need = lane_bits(df, hn::Not(hn::Gt(hn::Sub(hn::Load(df, r.seg_end), hn::Load(df, r.t)), eps))) & r.active;
         need; need &= need - 1) {
      const size_t l = size_t(__builtin_ctzll(need));
      r.st[l].t = r.t[l], r.st[l].seg_end = r.seg_end[l];
      if (step_segment(p, r.st[l], true, p.step)) {
        r.t[l] = r.st[l].t, r.seg_end[l] = r.st[l].seg_end, r.seg_len[l] = r.st[l].seg_len;
      } else {
        finish(r, l);
      }
    }
  };
  // One sample of every lane: step, lookup, transfer function, compositing; opaque rays end.
  auto sample = [&](RayPacket& r) {
    if (!r.active) return;
    samples += __builtin_popcountll(r.active);
    // step_take + ray_at + march_sample_points
    const VF ta = hn::Load(df, r.t), end = hn::Load(df, r.seg_end), next = hn::Add(ta, hn::Load(df, r.seg_len));
    const VF tb = hn::IfThenElse(hn::Lt(next, end), next, end);
    hn::Store(tb, df, r.t);
    const VF dt = hn::Sub(tb, ta);
    const VF ts = hn::Add(ta, hn::Mul(hn::Load(df, r.jit), dt));
    const VF ox = hn::Load(df, r.ox), oy = hn::Load(df, r.oy), oz = hn::Load(df, r.oz);
    const VF dx = hn::Load(df, r.dx), dy = hn::Load(df, r.dy), dz = hn::Load(df, r.dz);
    const VF ux = hn::Mul(hn::Add(ox, hn::Mul(dx, ts)), ibx);
    const VF uy = hn::Mul(hn::Add(oy, hn::Mul(dy, ts)), iby);
    const VF uz = hn::Mul(hn::Add(oz, hn::Mul(dz, ts)), ibz);
    // The next sample's rows, one step ahead: their loads overlap this sample's arithmetic.
    const VF tn = hn::Add(ts, hn::Load(df, r.seg_len));
    lanes.prefetch(df, hn::Mul(hn::Add(ox, hn::Mul(dx, tn)), ibx), hn::Mul(hn::Add(oy, hn::Mul(dy, tn)), iby),
                   hn::Mul(hn::Add(oz, hn::Mul(dz, tn)), ibz));
    const VF v = lanes.lookup(df, ux, uy, uz, r.active);

    // tf_lookup (clampf written as its compare-and-select, so every target matches the scalar code)
    const VF y = hn::Mul(hn::Sub(v, tf_lo), tf_scale);
    const VF yc = hn::IfThenElse(hn::Lt(y, zero), zero, hn::IfThenElse(hn::Gt(y, one), one, y));
    const VF x = hn::Mul(yc, tf_last);
    const auto i = hn::Min(hn::ConvertTo(di, x), tf_imax);
    const VF f = hn::Sub(x, hn::ConvertTo(df, i));
    auto channel = [&](int c) {
      VF a, b;
      GatherPairs(df, tf_soa.data() + size_t(c) * size_t(p.tf.n), i, &a, &b);
      return hn::Add(a, hn::Mul(hn::Sub(b, a), f));
    };
    const VF ca = channel(3);

    // corrected_alpha: the clamp, then 1 - (1 - alpha)^dt for the steps that are not one voxel long
    VF a = hn::IfThenElse(hn::Lt(ca, zero), zero, hn::IfThenElse(hn::Gt(ca, one), one, ca));
    // Where no lane is visible the compositing adds exact zeros: skip it and the colour lookups.
    if (!(lane_bits(df, hn::Ne(a, zero)) & r.active)) return;
    const auto partial = hn::Ne(dt, one);
    if (lane_bits(df, partial) & r.active) a = hn::IfThenElse(partial, hn::Sub(one, UnitPowVec(df, hn::Sub(one, a), dt)), a);
    const VF cr = channel(0), cg = channel(1), cb = channel(2);

    // march_shade's compositing
    const VF acc_w = hn::Load(df, r.aw);
    const VF w = hn::Mul(hn::Sub(one, acc_w), a);
    hn::Store(hn::Add(hn::Load(df, r.ar), hn::Mul(w, cr)), df, r.ar);
    hn::Store(hn::Add(hn::Load(df, r.ag), hn::Mul(w, cg)), df, r.ag);
    hn::Store(hn::Add(hn::Load(df, r.ab), hn::Mul(w, cb)), df, r.ab);
    const VF acc_w2 = hn::Add(acc_w, w);
    hn::Store(acc_w2, df, r.aw);
    for (uint64_t opaque = lane_bits(df, hn::Not(hn::Lt(acc_w2, alpha_stop))) & r.active; opaque;
         opaque &= opaque - 1)
      finish(r, size_t(__builtin_ctzll(opaque)));
  };

  // One packet per thread: a second one in flight to overlap gathers does not pay.
  RayPacket r;
  for (size_t l = 0; l < L && start(r, l); ++l) r.active |= uint64_t(1) << l;
  while (r.active) {
    refresh(r);
    sample(r);
  }
  return samples;
}

void UnitPowPackets(const float* b, const float* e, float* out, size_t n) {
  const hn::ScalableTag<float> df;
  const size_t L = hn::Lanes(df);
  for (size_t i = 0; i < n; i += L) {
    alignas(HWY_MAX_BYTES) float bl[RayPacket::kMaxLanes] = {}, el[RayPacket::kMaxLanes] = {}, ol[RayPacket::kMaxLanes];
    const size_t m = n - i < L ? n - i : L;
    std::memcpy(bl, b + i, m * sizeof(float));
    std::memcpy(el, e + i, m * sizeof(float));
    hn::Store(UnitPowVec(df, hn::Load(df, bl), hn::Load(df, el)), df, ol);
    std::memcpy(out + i, ol, m * sizeof(float));
  }
}

int64_t MarchGridPackets(const RenderParams& p, const GridView& g, TileCursor cursor, Vec4f* pixels) {
  GridLanes lanes{g};
  return MarchPackets(p, lanes, cursor, pixels);
}
int64_t MarchCachePackets(const RenderParams& p, const BrickCacheView& c, const RenderableField& source,
                          TileCursor cursor, Vec4f* pixels) {
  CacheLanes lanes{c, source};
  return MarchPackets(p, lanes, cursor, pixels);
}

}  // namespace HWY_NAMESPACE
}  // namespace vnr
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace vnr {
HWY_EXPORT(MarchGridPackets);
HWY_EXPORT(MarchCachePackets);
HWY_EXPORT(UnitPowPackets);
void unit_pow_packets(const float* b, const float* e, float* out, size_t n) {
  HWY_DYNAMIC_DISPATCH(UnitPowPackets)(b, e, out, n);
}
int64_t march_grid_packets(const RenderParams& p, const GridView& g, TileCursor cursor, Vec4f* pixels) {
  return HWY_DYNAMIC_DISPATCH(MarchGridPackets)(p, g, cursor, pixels);
}
int64_t march_cache_packets(const RenderParams& p, const BrickCacheView& c, const RenderableField& source,
                            TileCursor cursor, Vec4f* pixels) {
  return HWY_DYNAMIC_DISPATCH(MarchCachePackets)(p, c, source, cursor, pixels);
}
}  // namespace vnr
#endif
