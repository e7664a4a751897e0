#include "vnr/render/field.h"
#include "vnr/core/parallel.h"

namespace vnr {

void GridField::query(const float* x, const float* y, const float* z, int64_t n, float* out) const {
  parallel_for_range(n, 4096, [&](int64_t b, int64_t e) { grid_lookup_batch(g_, x + b, y + b, z + b, e - b, out + b); });
}

void NetworkField::query(const float* x, const float* y, const float* z, int64_t n, float* out) const {
  net_.infer_fn(
      n,
      [&](int64_t i, float* px, float* py, float* pz) {
        *px = x[i];
        *py = y[i];
        *pz = z[i];
      },
      out);
}

}  // namespace vnr
