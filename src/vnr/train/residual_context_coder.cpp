// A context-adaptive binary arithmetic coder for the residual field (residual_codec.cpp chooses it
// when it codes smaller than zstd). Each value is a zero flag, a sign and a magnitude; the zero flag's
// probability depends on how many of the three causal neighbours (x-1, y-1, z-1) are non-zero and how
// large they are, the sign's on the x-1 neighbour's sign: residuals cluster where the network errs.
#include <algorithm>
#include <cstdlib>
#include <memory>
#include "vnr/core/binary_coder.h"
#include "vnr/error.h"
#include "vnr/train/residual_context_coder.h"

namespace vnr {

namespace {

// The models: zero flag by neighbourhood, sign by the x-1 sign, unary magnitude bits by position and
// neighbourhood size, gamma length and mantissa bits by position.
struct Models {
  Prob zero[3][4][4], sign[3];
  MagnitudeModels<> magnitude[3];
  GammaModels<> gamma;
  Prob block[3][4];  // wavelet: a block's any-non-zero flag by its parent block (none, zero, not) and neighbours
};

struct Context {
  int parent, nonzero, mag, sign, size;  // parent bucket (0-2), neighbours non-zero (0-3), their |sum| bucket
                                         // (0-3), x-1 sign, size (0-2)
};

// With `parent` (wavelet coefficients), also the value at (x/2, y/2, z/2), which in the Mallat layout is
// the same orientation's coefficient one level coarser (coded before it, see kBlock).
Context context_of(const int32_t* q, Int3 d, int64_t x, int64_t y, int64_t z, int64_t i, bool parent) {
  const int32_t a = x > 0 ? q[i - 1] : 0, b = y > 0 ? q[i - d.x] : 0, c = z > 0 ? q[i - d.x * d.y] : 0;
  const int nonzero = (a != 0) + (b != 0) + (c != 0);
  const int64_t mag = std::abs(int64_t(a)) + std::abs(int64_t(b)) + std::abs(int64_t(c));
  const int bucket = mag == 0 ? 0 : mag <= 1 ? 1 : mag <= 3 ? 2 : 3;
  int up = 0;
  if (parent && i > 0) {
    const int64_t p = std::abs(int64_t(q[x / 2 + d.x * (y / 2 + d.y * (z / 2))]));
    up = p == 0 ? 0 : p <= 2 ? 1 : 2;
  }
  return {up, nonzero, bucket, a < 0 ? 0 : a == 0 ? 1 : 2, std::max(up, bucket == 0 ? 0 : bucket == 3 ? 2 : 1)};
}

template <typename Visit>
void for_each_voxel(Int3 d, Visit&& visit) {
  int64_t i = 0;
  for (int64_t z = 0; z < d.z; ++z)
    for (int64_t y = 0; y < d.y; ++y)
      for (int64_t x = 0; x < d.x; ++x, ++i) visit(x, y, z, i);
}

// Wavelet coefficients are mostly zero in large regions, where even a well-adapted zero flag costs
// ~0.01 bit each: they go in blocks of kBlock^3, raster order of blocks and within each, every block
// first flagged "any non-zero" (a zero block codes nothing more; 7-25 % smaller streams at 16-128x). Every
// context stays causal: x-1, y-1, z-1 and the parent (x/2, y/2, z/2) lie in earlier blocks or earlier
// in the same block.
constexpr int64_t kBlock = 8;

struct BlockGrid {
  Int3 n;
  std::vector<uint8_t> any;  // per block, once coded
  explicit BlockGrid(Int3 d)
      : n{(d.x + kBlock - 1) / kBlock, (d.y + kBlock - 1) / kBlock, (d.z + kBlock - 1) / kBlock},
        any(size_t(n.count()), 0) {}
  int64_t index(int64_t bx, int64_t by, int64_t bz) const { return bx + n.x * (by + n.y * bz); }
  // Context of block (bx, by, bz)'s flag: its parent block (0: itself, 1: zero, 2: not), neighbours set.
  std::pair<int, int> context(int64_t bx, int64_t by, int64_t bz) const {
    const int near = (bx > 0 && any[size_t(index(bx - 1, by, bz))]) + (by > 0 && any[size_t(index(bx, by - 1, bz))]) +
                     (bz > 0 && any[size_t(index(bx, by, bz - 1))]);
    const int64_t p = index(bx / 2, by / 2, bz / 2), self = index(bx, by, bz);
    return {p == self ? 0 : 1 + any[size_t(p)], near};
  }
};

// visit_block(bx, by, bz, visit_voxels) for every block; visit_voxels(visit) calls visit(x, y, z, i)
// for the block's voxels in raster order.
template <typename VisitBlock>
void for_each_block(Int3 d, const BlockGrid& g, VisitBlock&& visit_block) {
  for (int64_t bz = 0; bz < g.n.z; ++bz)
    for (int64_t by = 0; by < g.n.y; ++by)
      for (int64_t bx = 0; bx < g.n.x; ++bx)
        visit_block(bx, by, bz, [&](auto&& visit) {
          for (int64_t z = bz * kBlock; z < std::min(d.z, (bz + 1) * kBlock); ++z)
            for (int64_t y = by * kBlock; y < std::min(d.y, (by + 1) * kBlock); ++y)
              for (int64_t x = bx * kBlock; x < std::min(d.x, (bx + 1) * kBlock); ++x) visit(x, y, z, x + d.x * (y + d.y * z));
        });
}

void encode_value(BinaryEncoder& enc, Models& m, const Context& c, int32_t v) {
  if (std::abs(int64_t(v)) > kMaxContextMagnitude) fail("context coder: value {} is out of its range (2^30)", v);
  enc.bit(m.zero[c.parent][c.nonzero][c.mag], v != 0);
  if (v == 0) return;
  enc.bit(m.sign[c.sign], v < 0);
  encode_magnitude(enc, m.magnitude[c.size], m.gamma, uint64_t(std::abs(int64_t(v))));
}

int32_t decode_value(BinaryDecoder& dec, Models& m, const Context& c, const std::string& what) {
  if (!dec.bit(m.zero[c.parent][c.nonzero][c.mag])) return 0;
  const bool negative = dec.bit(m.sign[c.sign]);
  const uint64_t a = decode_magnitude(dec, m.magnitude[c.size], m.gamma);
  if (a == 0) fail("{}: the residual block is corrupted (code too long)", what);
  if (a > uint64_t(INT32_MAX)) fail("{}: the residual block is corrupted (value out of range)", what);
  return negative ? -int32_t(a) : int32_t(a);
}

}  // namespace

std::vector<uint8_t> context_encode(const int32_t* q, Int3 d, bool wavelet) {
  auto m = std::make_unique<Models>();
  BinaryEncoder enc;
  if (!wavelet) {
    for_each_voxel(d, [&](int64_t x, int64_t y, int64_t z, int64_t i) {
      encode_value(enc, *m, context_of(q, d, x, y, z, i, false), q[i]);
    });
    return enc.finish();
  }
  BlockGrid g(d);
  for_each_block(d, g, [&](int64_t bx, int64_t by, int64_t bz, auto&& voxels) {
    bool any = false;
    voxels([&](int64_t, int64_t, int64_t, int64_t i) { any = any || q[i] != 0; });
    const auto [parent, near] = g.context(bx, by, bz);
    enc.bit(m->block[parent][near], any);
    g.any[size_t(g.index(bx, by, bz))] = any;
    if (any)
      voxels([&](int64_t x, int64_t y, int64_t z, int64_t i) { encode_value(enc, *m, context_of(q, d, x, y, z, i, true), q[i]); });
  });
  return enc.finish();
}

void context_decode(const uint8_t* data, size_t n, Int3 d, int32_t* q, const std::string& what, bool wavelet) {
  auto m = std::make_unique<Models>();
  BinaryDecoder dec(data, n);
  if (!wavelet) {
    for_each_voxel(d, [&](int64_t x, int64_t y, int64_t z, int64_t i) {
      q[i] = decode_value(dec, *m, context_of(q, d, x, y, z, i, false), what);
    });
  } else {
    BlockGrid g(d);
    for_each_block(d, g, [&](int64_t bx, int64_t by, int64_t bz, auto&& voxels) {
      const auto [parent, near] = g.context(bx, by, bz);
      const bool any = dec.bit(m->block[parent][near]);
      g.any[size_t(g.index(bx, by, bz))] = any;
      voxels([&](int64_t x, int64_t y, int64_t z, int64_t i) {
        q[i] = any ? decode_value(dec, *m, context_of(q, d, x, y, z, i, true), what) : 0;
      });
    });
  }
  if (dec.overran()) fail("{}: the residual block is corrupted (truncated)", what);
}

}  // namespace vnr
