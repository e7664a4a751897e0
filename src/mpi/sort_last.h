#pragma once
// Sort-last compositing across ranks by direct send: every rank renders its bricks into full-frame
// premultiplied RGBA images; rank r receives rows row_band(height, r, N) of every brick image, composites
// them front to back in visibility order, and rank 0 gathers the bands. Each brick image crosses the
// network once ((N - 1) / N of its bytes), whatever the assignment of bricks to ranks.
#include <cstdint>
#include <vector>
#include "mpi/composite.h"

namespace vnr::mpi {

struct BrickImage {
  int brick = 0;                  // index into owner_of_brick
  const Image* image = nullptr;   // width x height, premultiplied, no background
};

struct CompositeStats {
  int64_t bytes_sent = 0;  // this rank's image bytes to other ranks (bands and the gather)
  double seconds = 0;
};

// Collective. owner_of_brick[b]: the rank holding brick b's image (every brick has one); order: the
// bricks front to back. Returns the composited image on rank 0 (without background), an empty one
// elsewhere. Without an MPI session it composites `mine` in one process.
Image composite_direct_send(const std::vector<BrickImage>& mine, const std::vector<int>& owner_of_brick,
                            const std::vector<int>& order, int width, int height, CompositeStats* stats = nullptr);

}  // namespace vnr::mpi
