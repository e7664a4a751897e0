// A context-adaptive binary arithmetic coder for the residual field (residual_codec.cpp chooses it
// when it codes smaller than zstd). Each value is a zero flag, a sign and a magnitude; the zero flag's
// probability depends on how many of the three causal neighbours (x-1, y-1, z-1) are non-zero and how
// large they are, the sign's on the x-1 neighbour's sign: residuals cluster where the network errs.
#include <algorithm>
#include <cstdlib>
#include <memory>
#include "vnr/core/binary_coder.h"
#include "vnr/core/error.h"
#include "vnr/train/residual_context_coder.h"

namespace vnr {

namespace {

// The models: zero flag by neighbourhood, sign by the x-1 sign, unary magnitude bits by position and
// neighbourhood size, gamma length and mantissa bits by position.
struct Models {
  Prob zero[4][4], sign[3];
  MagnitudeModels<> magnitude[3];
  GammaModels<> gamma;
};

struct Context {
  int nonzero, mag, sign, size;  // neighbours non-zero (0-3), their |sum| bucket (0-3), x-1 sign, size (0-2)
};

Context context_of(const int32_t* q, Int3 d, int64_t x, int64_t y, int64_t z, int64_t i) {
  const int32_t a = x > 0 ? q[i - 1] : 0, b = y > 0 ? q[i - d.x] : 0, c = z > 0 ? q[i - d.x * d.y] : 0;
  const int nonzero = (a != 0) + (b != 0) + (c != 0);
  const int64_t mag = std::abs(int64_t(a)) + std::abs(int64_t(b)) + std::abs(int64_t(c));
  const int bucket = mag == 0 ? 0 : mag <= 1 ? 1 : mag <= 3 ? 2 : 3;
  return {nonzero, bucket, a < 0 ? 0 : a == 0 ? 1 : 2, bucket == 0 ? 0 : bucket == 3 ? 2 : 1};
}

template <typename Visit>
void for_each_voxel(Int3 d, Visit&& visit) {
  int64_t i = 0;
  for (int64_t z = 0; z < d.z; ++z)
    for (int64_t y = 0; y < d.y; ++y)
      for (int64_t x = 0; x < d.x; ++x, ++i) visit(x, y, z, i);
}

}  // namespace

std::vector<uint8_t> context_encode(const int32_t* q, Int3 d) {
  auto m = std::make_unique<Models>();
  BinaryEncoder enc;
  for_each_voxel(d, [&](int64_t x, int64_t y, int64_t z, int64_t i) {
    const Context c = context_of(q, d, x, y, z, i);
    const int32_t v = q[i];
    const int mag_ctx = c.size;
    enc.bit(m->zero[c.nonzero][c.mag], v != 0);
    if (v == 0) return;
    enc.bit(m->sign[c.sign], v < 0);
    encode_magnitude(enc, m->magnitude[mag_ctx], m->gamma, uint64_t(std::abs(int64_t(v))));
  });
  return enc.finish();
}

void context_decode(const uint8_t* data, size_t n, Int3 d, int32_t* q, const std::string& what) {
  auto m = std::make_unique<Models>();
  BinaryDecoder dec(data, n);
  for_each_voxel(d, [&](int64_t x, int64_t y, int64_t z, int64_t i) {
    const Context c = context_of(q, d, x, y, z, i);
    const int mag_ctx = c.size;
    if (!dec.bit(m->zero[c.nonzero][c.mag])) {
      q[i] = 0;
      return;
    }
    const bool negative = dec.bit(m->sign[c.sign]);
    const uint64_t a = decode_magnitude(dec, m->magnitude[mag_ctx], m->gamma);
    if (a == 0) fail("{}: the residual block is corrupted (code too long)", what);
    if (a > uint64_t(INT32_MAX)) fail("{}: the residual block is corrupted (value out of range)", what);
    q[i] = negative ? -int32_t(a) : int32_t(a);
  });
  if (dec.overran()) fail("{}: the residual block is corrupted (truncated)", what);
}

}  // namespace vnr
