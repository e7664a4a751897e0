#pragma once
// The brick cache as its lookups read it (fields/brick_cache.h): plain arrays, written only between
// frames, read by every sample of a frame. The lookup (BrickCacheLookup::sample) is written once for
// the host cache -- the scalar lookup here, the SIMD one of grid_packets.cpp computes the same -- and
// for its copy in GPU memory (render_cuda/cache_copy.cuh); what a read records differs: the host cache
// stamps bricks and queues requests (BrickCacheView), a copy stamps pool slots and appends requests
// that the host cache takes back after the frame (BrickCacheCopyReads).
#include <atomic>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>
#include "vnr/grid_view.h"
#include "vnr/hd.h"

namespace vnr {

struct RenderParams;  // render/integrators.h

struct CacheLevelView {
  int32_t nx, ny, nz;     // voxels of the level
  int32_t bx, by, bz;     // bricks per axis
  const int32_t* slot;    // per brick: its slot in the pool, -1 when not decoded
};

// Levels of detail blend: over the last quarter (in log2) of the distances a level l is read at, where a
// sample's footprint m (level-0 voxels per lod_pixels pixels) nears 2^(l+1), it mixes in level l + 1 by
// t = (m / 2^l - kLodBlendStart) / (2 - kLodBlendStart), so the level read changes continuously with
// distance (no seam between bricks of two levels), and no finer brick is read than without blending.
constexpr float kLodBlendStart = 1.68179283f;  // 2^(3/4)
constexpr float kLodBlendInverse = 1 / (2 - kLodBlendStart);

// The bits of a value as another type of the same size, on both sides.
template <class To, class From>
VNR_HD VNR_INLINE To bits_as(From v) {
  static_assert(sizeof(To) == sizeof(From));
  return __builtin_bit_cast(To, v);
}

// What a lookup reads: the levels' page tables and the pool (host or GPU memory), and the view's levels
// of detail. `Reads` records what a sample reads: read(level, brick, slot), ask(level, brick) for a
// brick not decoded, missed() when no level answers.
struct BrickCacheLookup {
  static constexpr int kMaxLevels = 24;
  CacheLevelView level[kMaxLevels];
  int levels = 0;
  // The level of detail of the current view: a sample at u is at world position u * box, distance d
  // from the eye, and covers m = d * lod_scale level-0 voxels (CachedField::update_levels).
  float eye[3] = {0, 0, 0}, box[3] = {1, 1, 1};
  float lod_scale = 0;
  bool level0_only = false;      // box_reads_level0() of the view: no sample needs level_at
  const float* pool = nullptr;   // slot s holds (B+1)^3 voxels from pool + s * brick_floats, x fastest
  int64_t brick_floats = 0;
  int shift = 5;                 // log2 B
  int32_t sy = 33, sz = 33 * 33;  // strides inside a brick
  bool coarser = false;          // misses read the nearest decoded coarser level (CacheMisses::Coarser)

  // The level a sample at u reads: floor(log2 m), within [0, levels - 1]; *t > 0 where it blends with
  // the next coarser level (value = this + (coarser - this) * t), else 0.
  VNR_HD VNR_INLINE int level_at(float x, float y, float z, float* t = nullptr) const {
    const float dx = x * box[0] - eye[0], dy = y * box[1] - eye[1], dz = z * box[2] - eye[2];
    const float m = sqrtf(dx * dx + dy * dy + dz * dz) * lod_scale;
    const uint32_t bits = bits_as<uint32_t>(m);
    const int e = int(bits >> 23) - 127;  // m >= 0: its exponent is floor(log2 m)
    if (t) *t = 0;
    if (e < 0) return 0;
    if (e >= levels - 1) return levels - 1;
    const float mant = bits_as<float>((bits & 0x7fffffu) | 0x3f800000u);  // m / 2^e, in [1, 2)
    if (t && mant >= kLodBlendStart) *t = (mant - kLodBlendStart) * kLodBlendInverse;
    return e;
  }
  // True when every sample in the box reads level 0 unblended (level_at returns 0 with t = 0): one
  // level, or even the box's farthest corner is short of level 0's blend (a margin for rounding).
  VNR_HD VNR_INLINE bool box_reads_level0() const {
    if (levels <= 1) return true;
    float far2 = 0;
    for (int k = 0; k < 3; ++k) {
      const float d = fmaxf(fabsf(eye[k]), fabsf(box[k] - eye[k]));
      far2 += d * d;
    }
    return sqrtf(far2) * lod_scale < 0.99f * kLodBlendStart;
  }
  // The cached value at u, or *miss = true when a level it reads (or, coarser, every level from it up)
  // is not decoded. Where it blends two levels, each is the arithmetic of grid_lookup over that level's
  // full decode.
  VNR_HD_TEMPLATE template <class Reads>
  VNR_HD VNR_INLINE float sample(const Reads& r, float x, float y, float z, bool* miss) const {
    if (level0_only) return sample_level(r, 0, x, y, z, miss);
    float t;
    const int l = level_at(x, y, z, &t);
    if (t == 0) return sample_level(r, l, x, y, z, miss);
    const float fine = sample_level(r, l, x, y, z, miss);
    const float coarse = sample_level(r, l + 1, x, y, z, miss);
    return *miss ? 0 : fine + (coarse - fine) * t;
  }
  // The value at u from level l, or (coarser) the nearest decoded level above it.
  VNR_HD_TEMPLATE template <class Reads>
  VNR_HD VNR_INLINE float sample_level(const Reads& r, int l, float x, float y, float z, bool* miss) const {
    for (bool first = true;; first = false) {
      const CacheLevelView& L = level[l];
      const CellAxis ax = cell_axis(x, L.nx), ay = cell_axis(y, L.ny), az = cell_axis(z, L.nz);
      const int32_t bx = ax.i0 >> shift, by = ay.i0 >> shift, bz = az.i0 >> shift;
      const int64_t b = bx + L.bx * (by + int64_t(L.by) * bz);
      if (const int32_t s = L.slot[b]; s >= 0) {
        r.read(l, b, s);
        const float* base = pool + s * brick_floats +
                            ((ax.i0 - (bx << shift)) + (ay.i0 - (by << shift)) * sy + (az.i0 - (bz << shift)) * sz);
        const int32_t dx = ax.i1 - ax.i0, dy = (ay.i1 - ay.i0) * sy, dz = (az.i1 - az.i0) * sz;
        const float v[8] = {base[0],  base[dx],      base[dy],      base[dx + dy],
                            base[dz], base[dx + dz], base[dy + dz], base[dx + dy + dz]};
        return trilinear_corners(ax, ay, az, v);
      }
      if (first) r.ask(l, b);
      if (!coarser || l + 1 == levels) {
        r.missed();
        *miss = true;
        return 0;
      }
      ++l;
    }
  }
  // Bricks of levels [0, l): where level l's entries start in one table of every level's bricks.
  int64_t level_offset(int l) const {
    int64_t o = 0;
    for (int k = 0; k < l; ++k) o += int64_t(level[k].bx) * level[k].by * level[k].bz;
    return o;
  }
  // This lookup over a copy's page table of every level (level_offset order) and pool; its misses read
  // the nearest decoded coarser level.
  BrickCacheLookup over_copy(const int32_t* table, const float* copy_pool) const {
    BrickCacheLookup c = *this;
    for (int l = 0; l < levels; ++l) c.level[l].slot = table + level_offset(l);
    c.pool = copy_pool;
    c.coarser = true;
    return c;
  }
};

// The host cache's lookup: a read stamps its brick with the frame (least recently used eviction), a
// miss asks the cache for the brick (decoded before a later frame) and counts.
struct BrickCacheView : BrickCacheLookup {
  std::atomic<uint32_t>* used[kMaxLevels] = {};  // per brick of a level: the last frame that read it
  uint32_t frame = 1;
  // Asks for brick b of level l (a miss): the cache decodes it before a later frame.
  void (*ask)(void* cache, int l, int64_t b) = nullptr;
  void* cache = nullptr;
  std::atomic<int64_t>* misses = nullptr;  // samples of the frame that read the source

  struct Reads {
    const BrickCacheView* v;
    void read(int l, int64_t b, int32_t) const { v->touch(l, b); }
    void ask(int l, int64_t b) const { v->ask(v->cache, l, b); }
    void missed() const { v->misses->fetch_add(1, std::memory_order_relaxed); }
  };
  VNR_INLINE void touch(int l, int64_t b) const {
    if (used[l][b].load(std::memory_order_relaxed) != frame) used[l][b].store(frame, std::memory_order_relaxed);
  }
  VNR_INLINE float sample(float x, float y, float z, bool* miss) const {
    return BrickCacheLookup::sample(Reads{this}, x, y, z, miss);
  }
};

// Relaxed atomics on both sides: the GPU's own, GCC's builtins on the host (the copy's reads run on the
// host in tests).
VNR_HD VNR_INLINE uint32_t relaxed_load(const uint32_t* p) {
#if defined(__CUDA_ARCH__)
  return *static_cast<const volatile uint32_t*>(p);
#else
  return __atomic_load_n(p, __ATOMIC_RELAXED);
#endif
}
VNR_HD VNR_INLINE void relaxed_store(uint32_t* p, uint32_t v) {
#if defined(__CUDA_ARCH__)
  *static_cast<volatile uint32_t*>(p) = v;
#else
  __atomic_store_n(p, v, __ATOMIC_RELAXED);
#endif
}
VNR_HD VNR_INLINE uint32_t exchange(uint32_t* p, uint32_t v) {
#if defined(__CUDA_ARCH__)
  return atomicExch(p, v);
#else
  return __atomic_exchange_n(p, v, __ATOMIC_RELAXED);
#endif
}
template <class T>  // uint32_t or unsigned long long (atomicAdd's)
VNR_HD VNR_INLINE T fetch_add(T* p, T v) {
#if defined(__CUDA_ARCH__)
  return atomicAdd(p, v);
#else
  return __atomic_fetch_add(p, v, __ATOMIC_RELAXED);
#endif
}

// What a frame over a copy of the cache (the GPU's) records for the host cache to take back after it
// (BrickCacheCopySource::take_reads): the frame that last read each pool slot, and the bricks asked for,
// each once a frame (the first `capacity`; the rest are asked for again by the next frames).
struct BrickCacheCopyReads {
  uint32_t* slot_read = nullptr;  // per pool slot
  uint32_t* asked = nullptr;      // per brick of every level, from level_offset[l]: the last frame that asked
  int64_t level_offset[BrickCacheLookup::kMaxLevels] = {};
  int32_t* requests = nullptr;    // (level, brick) pairs
  uint32_t* n_requests = nullptr;
  uint32_t capacity = 0;
  uint32_t frame = 0;
  unsigned long long* misses = nullptr;

  void set_levels(const BrickCacheLookup& c) {  // the levels' offsets of the cache copied
    for (int l = 0; l < c.levels; ++l) level_offset[l] = c.level_offset(l);
  }
  VNR_HD VNR_INLINE void read(int, int64_t, int32_t slot) const {
    if (relaxed_load(slot_read + slot) != frame) relaxed_store(slot_read + slot, frame);
  }
  VNR_HD VNR_INLINE void ask(int l, int64_t b) const {
    uint32_t* a = asked + level_offset[l] + b;
    if (relaxed_load(a) == frame || exchange(a, frame) == frame) return;
    const uint32_t n = fetch_add(n_requests, 1u);
    if (n < capacity) requests[2 * n] = l, requests[2 * n + 1] = int32_t(b);
  }
  VNR_HD VNR_INLINE void missed() const { fetch_add(misses, 1ull); }

  // One thread's reads within one frame: a run of samples in one slot stamps it once (a ray's samples
  // mostly stay in a brick), sparing a global load per sample.
  struct Memo {
    const BrickCacheCopyReads* r;
    mutable int32_t last_slot = -1;
    VNR_HD VNR_INLINE void read(int l, int64_t b, int32_t slot) const {
      if (slot != last_slot) last_slot = slot, r->read(l, b, slot);
    }
    VNR_HD VNR_INLINE void ask(int l, int64_t b) const { r->ask(l, b); }
    VNR_HD VNR_INLINE void missed() const { r->missed(); }
  };
};

// What changed in a cache since its copy was last brought up to date (BrickCacheCopySource::take_changes).
struct BrickCacheChanges {
  std::vector<int32_t> slots;                        // pool slots whose voxels were written, ascending
  std::vector<std::pair<int64_t, int32_t>> entries;  // (level_offset + brick, its slot or -1), one per brick
};

// A brick cache that a renderer keeps a copy of where it renders (the GPU renderer: the pool and page
// tables in GPU memory). Per frame the renderer calls begin_frame (the cache decodes, on the host, what
// earlier frames asked for), take_changes (it copies what changed), renders from its copy, and hands
// back what the frame read and asked for with take_reads: the cache's own priorities, budget and
// eviction decide, the same cache as the host's frames read.
class BrickCacheCopySource {
public:
  virtual ~BrickCacheCopySource() = default;
  virtual void begin_frame(const RenderParams& p) const = 0;
  // The lookup as the host reads it: the copy takes its levels, strides and view, with its own tables.
  virtual const BrickCacheView& view() const = 0;
  virtual int32_t pool_slots() const = 0;
  // Everything resident (a new copy: from_scratch), else what changed since the last call.
  virtual BrickCacheChanges take_changes(bool from_scratch) const = 0;
  // A frame over the copy: slot_read[s] = the last frame that read pool slot s, n requests (level,
  // brick), and the samples no level answered.
  virtual void take_reads(const uint32_t* slot_read, const int32_t* requests, int64_t n, int64_t misses) const = 0;
};

// A copy's upkeep before frame p, the GPU's and the tests' alike: the host cache prepares the frame, then
// copy_slots(first, count, voxels) takes each run of consecutive slots written (one copy a run) and
// set_entries(entries) the page-table entries set (everything resident when from_scratch). Returns the
// host's lookup, for the copy's own (over_copy).
template <class CopySlots, class SetEntries>
const BrickCacheView& update_cache_copy(const BrickCacheCopySource& src, const RenderParams& p, bool from_scratch,
                                        const CopySlots& copy_slots, const SetEntries& set_entries) {
  src.begin_frame(p);
  const BrickCacheView& v = src.view();
  const BrickCacheChanges ch = src.take_changes(from_scratch);
  for (size_t i = 0, j; i < ch.slots.size(); i = j) {
    for (j = i + 1; j < ch.slots.size() && ch.slots[j] == ch.slots[j - 1] + 1;) ++j;
    copy_slots(ch.slots[i], int32_t(j - i), v.pool + int64_t(ch.slots[i]) * v.brick_floats);
  }
  if (!ch.entries.empty()) set_entries(ch.entries);
  return v;
}

}  // namespace vnr
