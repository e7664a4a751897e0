#include "vnr/render/field.h"
#include <cstring>
#include "vnr/core/parallel.h"

namespace vnr {

void GridField::query(const float* x, const float* y, const float* z, int64_t n, float* out) const {
  parallel_for_range(n, 4096, [&](int64_t b, int64_t e) { grid_lookup_batch(g_, x + b, y + b, z + b, e - b, out + b); });
}

void NetworkField::query(const float* x, const float* y, const float* z, int64_t n, float* out) const {
  net_.infer_fn(
      n,
      [&](int64_t first, int64_t count, float* px, float* py, float* pz) {  // whole chunks: three copies
        std::memcpy(px, x + first, sizeof(float) * size_t(count));
        std::memcpy(py, y + first, sizeof(float) * size_t(count));
        std::memcpy(pz, z + first, sizeof(float) * size_t(count));
      },
      out);
}

}  // namespace vnr
