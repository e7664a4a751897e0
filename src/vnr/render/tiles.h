#pragma once
// Pixels in square tiles: rays of neighbouring pixels read neighbouring voxels, so every renderer
// visits an image tile by tile.
#include <atomic>
#include <cstdint>

namespace vnr {

// The pixels of a W x H image cut into size x size tiles, each tile in row order. With `claim`, the
// tiles are claimed one at a time from that counter (shared by the threads, starting at 0) by whichever
// thread is free: a thread slowed by another process takes fewer, so a frame no longer waits for its
// slowest thread. Without it, the tiles tile, tile + stride, ... (the streaming queues start in the
// order of all tiles: tile 0, stride 1). A pixel's value never depends on the thread that renders it.
struct TileCursor {
  int width = 0, height = 0, size = 8;
  int64_t tile = 0, stride = 1;
  std::atomic<int64_t>* claim = nullptr;
  int k = 0;             // next pixel within the current tile
  bool started = false;  // the current tile was claimed (or, without a counter, is `tile`)
  bool next(int* ix, int* iy) {
    const int tiles_x = (width + size - 1) / size;
    const int64_t n_tiles = int64_t(tiles_x) * ((height + size - 1) / size);
    for (;;) {
      if (!started) {
        if (claim) tile = claim->fetch_add(1, std::memory_order_relaxed);
        started = true;
      }
      if (tile >= n_tiles) return false;
      const int x0 = int(tile % tiles_x) * size, y0 = int(tile / tiles_x) * size;
      while (k < size * size) {
        const int x = x0 + k % size, y = y0 + k / size;
        ++k;
        if (x < width && y < height) {
          *ix = x, *iy = y;
          return true;
        }
      }
      k = 0;
      started = false;
      if (!claim) tile += stride;
    }
  }
};

}  // namespace vnr
