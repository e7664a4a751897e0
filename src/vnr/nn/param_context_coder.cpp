// Each index is a zero flag, a sign and a magnitude (core/binary_coder.h), each bit's probability
// conditioned on what the decoder already has: the entry's previous feature, the same feature of the
// previous entry (for hashed levels mostly the x-neighbour: the hash xors x into the index, so entries
// e and e^1 share y and z) and, on dense levels, the y- and z-neighbours. Trained grids keep entries
// that few samples reach near zero in every feature, and smooth fields make neighbours alike.
#include "vnr/nn/param_context_coder.h"
#include <algorithm>
#include <cstdlib>
#include <memory>
#include "vnr/core/binary_coder.h"

namespace vnr {
namespace {

constexpr int kFeatureContexts = 4, kBuckets = 4, kMagnitudeContexts = 5;

int bucket(int64_t a) { return a == 0 ? 0 : a == 1 ? 1 : a <= 3 ? 2 : 3; }
int sign3(int32_t v) { return v < 0 ? 0 : v == 0 ? 1 : 2; }

struct Models {
  CountingProb zero[kFeatureContexts][kBuckets][kBuckets][kBuckets];
  CountingProb sign[3][3];
  MagnitudeModels<CountingProb> magnitude[kMagnitudeContexts];
  GammaModels<CountingProb> gamma;
};

struct Context {
  int zero_f, zero_a, zero_b, zero_s;  // feature, previous feature, previous entry, dense neighbours
  int sign_a, sign_b, magnitude;
};

// The context of index i from indices before it.
Context context_of(const int32_t* q, uint64_t i, IndexLayout L) {
  const uint64_t F = L.entry, e = i / F, f = i % F;
  const int32_t a = f > 0 ? q[i - 1] : 0;
  int32_t b = e > 0 ? q[i - F] : 0, c = 0, d = 0;
  if (L.res > 0) {
    const uint64_t r = L.res, x = e % r, y = (e / r) % r, z = e / (r * r);
    if (z < r) {  // a dense level's entries past res^3 (tcnn rounds the table up) have no position
      b = x > 0 ? b : 0;
      c = y > 0 ? q[i - r * F] : 0;
      d = z > 0 ? q[i - r * r * F] : 0;
    }
  }
  const int64_t aa = std::abs(int64_t(a)), ab = std::abs(int64_t(b)), as = std::abs(int64_t(c)) + std::abs(int64_t(d));
  const int64_t m = std::max({aa, ab, as});
  return {int(std::min<uint64_t>(f, kFeatureContexts - 1)), bucket(aa), bucket(ab), bucket(as),
          sign3(a), sign3(b), m == 0 ? 0 : m == 1 ? 1 : m <= 3 ? 2 : m <= 7 ? 3 : 4};
}

}  // namespace

std::vector<uint8_t> encode_param_indices(const int32_t* q, uint64_t n, IndexLayout L) {
  if (L.entry == 0) L.entry = 1;
  auto m = std::make_unique<Models>();
  BinaryEncoder enc;
  for (uint64_t i = 0; i < n; ++i) {
    const Context c = context_of(q, i, L);
    const int32_t v = q[i];
    enc.bit(m->zero[c.zero_f][c.zero_a][c.zero_b][c.zero_s], v != 0);
    if (v == 0) continue;
    enc.bit(m->sign[c.sign_a][c.sign_b], v < 0);
    encode_magnitude(enc, m->magnitude[c.magnitude], m->gamma, uint64_t(std::abs(int64_t(v))));
  }
  return enc.finish();
}

bool decode_param_indices(const uint8_t* data, size_t bytes, uint64_t n, IndexLayout L, int32_t* q) {
  if (L.entry == 0) L.entry = 1;
  auto m = std::make_unique<Models>();
  BinaryDecoder dec(data, bytes);
  for (uint64_t i = 0; i < n; ++i) {
    const Context c = context_of(q, i, L);
    if (!dec.bit(m->zero[c.zero_f][c.zero_a][c.zero_b][c.zero_s])) {
      q[i] = 0;
      continue;
    }
    const bool negative = dec.bit(m->sign[c.sign_a][c.sign_b]);
    const uint64_t a = decode_magnitude(dec, m->magnitude[c.magnitude], m->gamma);
    if (a == 0 || a > uint64_t(INT32_MAX)) return false;
    q[i] = negative ? -int32_t(a) : int32_t(a);
    if ((i & 4095) == 0 && dec.overran()) return false;
  }
  return !dec.overran();
}

}  // namespace vnr
