#pragma once
// The brick cache as its lookups read it (fields/brick_cache.h): plain arrays, written only between
// frames, read by every sample of a frame, the scalar lookup here and the SIMD one of grid_packets.cpp.
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstring>
#include "vnr/grid_view.h"
#include "vnr/hd.h"

namespace vnr {

struct CacheLevelView {
  int32_t nx, ny, nz;     // voxels of the level
  int32_t bx, by, bz;     // bricks per axis
  const int32_t* slot;    // per brick: its slot in the pool, -1 when not decoded
  std::atomic<uint32_t>* used;  // per brick: the last frame that read it
};

// Levels of detail blend: over the last quarter (in log2) of the distances a level l is read at, where a
// sample's footprint m (level-0 voxels per lod_pixels pixels) nears 2^(l+1), it mixes in level l + 1 by
// t = (m / 2^l - kLodBlendStart) / (2 - kLodBlendStart), so the level read changes continuously with
// distance (no seam between bricks of two levels), and no finer brick is read than without blending.
constexpr float kLodBlendStart = 1.68179283f;  // 2^(3/4)
constexpr float kLodBlendInverse = 1 / (2 - kLodBlendStart);

struct BrickCacheView {
  static constexpr int kMaxLevels = 24;
  CacheLevelView level[kMaxLevels];
  int levels = 0;
  // The level of detail of the current view: a sample at u is at world position u * box, distance d
  // from the eye, and covers m = d * lod_scale level-0 voxels (CachedField::update_levels).
  float eye[3] = {0, 0, 0}, box[3] = {1, 1, 1};
  float lod_scale = 0;
  const float* pool = nullptr;   // slot s holds (B+1)^3 voxels from pool + s * brick_floats, x fastest
  int64_t brick_floats = 0;
  int shift = 5;                 // log2 B
  int32_t sy = 33, sz = 33 * 33;  // strides inside a brick
  uint32_t frame = 1;
  bool coarser = false;          // misses read the nearest decoded coarser level (CacheMisses::Coarser)
  // Asks for brick b of level l (a miss): the cache decodes it before a later frame.
  void (*ask)(void* cache, int l, int64_t b) = nullptr;
  void* cache = nullptr;
  std::atomic<int64_t>* misses = nullptr;  // samples of the frame that read the source

  // The level a sample at u reads: floor(log2 m), within [0, levels - 1]; *t > 0 where it blends with
  // the next coarser level (value = this + (coarser - this) * t), else 0.
  VNR_INLINE int level_at(float x, float y, float z, float* t = nullptr) const {
    const float dx = x * box[0] - eye[0], dy = y * box[1] - eye[1], dz = z * box[2] - eye[2];
    const float m = std::sqrt(dx * dx + dy * dy + dz * dz) * lod_scale;
    uint32_t bits;
    std::memcpy(&bits, &m, 4);
    const int e = int(bits >> 23) - 127;  // m >= 0: its exponent is floor(log2 m)
    if (t) *t = 0;
    if (e < 0) return 0;
    if (e >= levels - 1) return levels - 1;
    const uint32_t mant_bits = (bits & 0x7fffffu) | 0x3f800000u;  // m / 2^e, in [1, 2)
    float mant;
    std::memcpy(&mant, &mant_bits, 4);
    if (t && mant >= kLodBlendStart) *t = (mant - kLodBlendStart) * kLodBlendInverse;
    return e;
  }
  VNR_INLINE void touch(const CacheLevelView& L, int64_t b) const {
    if (L.used[b].load(std::memory_order_relaxed) != frame) L.used[b].store(frame, std::memory_order_relaxed);
  }
  // The cached value at u, or *miss = true when a level it reads (or, coarser, every level from it up)
  // is not decoded. Where it blends two levels, each is the arithmetic of grid_lookup over that level's
  // full decode.
  VNR_INLINE float sample(float x, float y, float z, bool* miss) const {
    float t;
    const int l = level_at(x, y, z, &t);
    if (t == 0) return sample_level(l, x, y, z, miss);
    const float fine = sample_level(l, x, y, z, miss);
    const float coarse = sample_level(l + 1, x, y, z, miss);
    return *miss ? 0 : fine + (coarse - fine) * t;
  }
  // The value at u from level l, or (coarser) the nearest decoded level above it.
  VNR_INLINE float sample_level(int l, float x, float y, float z, bool* miss) const {
    for (bool first = true;; first = false) {
      const CacheLevelView& L = level[l];
      const CellAxis ax = cell_axis(x, L.nx), ay = cell_axis(y, L.ny), az = cell_axis(z, L.nz);
      const int32_t bx = ax.i0 >> shift, by = ay.i0 >> shift, bz = az.i0 >> shift;
      const int64_t b = bx + L.bx * (by + int64_t(L.by) * bz);
      if (const int32_t s = L.slot[b]; s >= 0) {
        touch(L, b);
        const float* base = pool + s * brick_floats +
                            ((ax.i0 - (bx << shift)) + (ay.i0 - (by << shift)) * sy + (az.i0 - (bz << shift)) * sz);
        const int32_t dx = ax.i1 - ax.i0, dy = (ay.i1 - ay.i0) * sy, dz = (az.i1 - az.i0) * sz;
        const float v[8] = {base[0],  base[dx],      base[dy],      base[dx + dy],
                            base[dz], base[dx + dz], base[dy + dz], base[dx + dy + dz]};
        return trilinear_corners(ax, ay, az, v);
      }
      if (first) ask(cache, l, b);
      if (!coarser || l + 1 == levels) {
        misses->fetch_add(1, std::memory_order_relaxed);
        *miss = true;
        return 0;
      }
      ++l;
    }
  }
};

}  // namespace vnr
