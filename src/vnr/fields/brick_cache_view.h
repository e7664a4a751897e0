#pragma once
// The brick cache as its lookups read it (fields/brick_cache.h): plain arrays, written only between
// frames, read by every sample of a frame, the scalar lookup here and the SIMD one of grid_packets.cpp.
#include <atomic>
#include <cstdint>
#include "vnr/core/grid_view.h"
#include "vnr/hd.h"

namespace vnr {

struct CacheLevelView {
  int32_t nx, ny, nz;     // voxels of the level
  int32_t bx, by, bz;     // bricks per axis
  const int32_t* slot;    // per brick: its slot in the pool, -1 when not decoded
  std::atomic<uint32_t>* used;  // per brick: the last frame that read it
};

struct BrickCacheView {
  static constexpr int kMaxLevels = 24;
  CacheLevelView level[kMaxLevels];
  int levels = 0;
  const int32_t* lod = nullptr;  // per level-0 brick: the level its samples read
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

  // The level a sample at u reads.
  VNR_INLINE int level_at(float x, float y, float z) const {
    const CacheLevelView& L = level[0];
    const CellAxis ax = cell_axis(x, L.nx), ay = cell_axis(y, L.ny), az = cell_axis(z, L.nz);
    return lod[(ax.i0 >> shift) + L.bx * ((ay.i0 >> shift) + int64_t(L.by) * (az.i0 >> shift))];
  }
  VNR_INLINE void touch(const CacheLevelView& L, int64_t b) const {
    if (L.used[b].load(std::memory_order_relaxed) != frame) L.used[b].store(frame, std::memory_order_relaxed);
  }
  // The cached value at u, or *miss = true when the level asked for (or, coarser, every level from it up)
  // is not decoded. Same voxels and arithmetic as grid_lookup over the level's full decode.
  VNR_INLINE float sample(float x, float y, float z, bool* miss) const {
    int l = level_at(x, y, z);
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
