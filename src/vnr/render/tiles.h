#pragma once
// Pixels in square tiles: rays of neighbouring pixels read neighbouring voxels, so every renderer
// visits an image tile by tile.
#include <cstdint>
#include "vnr/core/hd.h"

namespace vnr {

// The pixels of tiles first, first + stride, ... of a W x H image cut into size x size tiles, each
// tile in row order. Each thread of the in-shader renderer takes tiles t, t + threads, ...; the
// streaming queues start in the order of all tiles.
struct TileCursor {
  int width = 0, height = 0, size = 8;
  int64_t tile = 0, stride = 1;
  int k = 0;  // next pixel within the current tile
  VNR_HD bool next(int* ix, int* iy) {
    const int tiles_x = (width + size - 1) / size;
    const int64_t n_tiles = int64_t(tiles_x) * ((height + size - 1) / size);
    while (tile < n_tiles) {
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
      tile += stride;
    }
    return false;
  }
};

}  // namespace vnr
