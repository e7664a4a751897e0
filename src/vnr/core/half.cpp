#include "vnr/core/half.h"
#include "vnr/core/parallel.h"

namespace vnr {
void floats_to_halves(const float* in, uint16_t* out, size_t n) {
  parallel_for_range(int64_t(n), 1 << 16, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) out[i] = float_to_half(in[i]);
  });
}
void halves_to_floats(const uint16_t* in, float* out, size_t n) {
  parallel_for_range(int64_t(n), 1 << 16, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) out[i] = half_to_float(in[i]);
  });
}
}  // namespace vnr
