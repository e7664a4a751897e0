// A context-adaptive binary arithmetic coder for the residual field (residual_codec.cpp chooses it
// when it codes smaller than zstd). Each value is a zero flag, a sign and a magnitude; the zero flag's
// probability depends on how many of the three causal neighbours (x-1, y-1, z-1) are non-zero and how
// large they are, the sign's on the x-1 neighbour's sign: residuals cluster where the network errs.
#include <algorithm>
#include <cstdlib>
#include <memory>
#include "vnr/core/error.h"
#include "vnr/train/residual_context_coder.h"

namespace vnr {

namespace {

constexpr int kProbBits = 12, kAdapt = 5;
constexpr uint32_t kTop = 1u << 24;
constexpr int kUnary = 14;    // magnitudes 1..kUnary in unary, larger ones Elias-gamma after it
constexpr int kMaxBits = 31;  // a gamma code longer than this is corruption

struct Prob {
  uint16_t p = 1 << (kProbBits - 1);  // probability of a 0 bit, in 1/4096
};

class Encoder {
public:
  void bit(Prob& pr, int b) {
    const uint32_t bound = (range_ >> kProbBits) * pr.p;
    if (b == 0) {
      range_ = bound;
      pr.p = uint16_t(pr.p + (((1 << kProbBits) - pr.p) >> kAdapt));
    } else {
      low_ += bound;
      range_ -= bound;
      pr.p = uint16_t(pr.p - (pr.p >> kAdapt));
    }
    while (range_ < kTop) {
      range_ <<= 8;
      shift_low();
    }
  }
  std::vector<uint8_t> finish() {
    for (int i = 0; i < 5; ++i) shift_low();
    return std::move(out_);
  }

private:
  // Emits the top byte of low, holding back 0xFF bytes until a carry can no longer change them.
  void shift_low() {
    if (uint32_t(low_) < 0xFF000000u || (low_ >> 32) != 0) {
      const uint8_t carry = uint8_t(low_ >> 32);
      uint8_t held = cache_;
      do {
        out_.push_back(uint8_t(held + carry));
        held = 0xFF;
      } while (--pending_ != 0);
      cache_ = uint8_t(low_ >> 24);
    }
    ++pending_;
    low_ = (low_ & 0x00FFFFFFu) << 8;
  }
  uint64_t low_ = 0;
  uint32_t range_ = 0xFFFFFFFFu;
  uint8_t cache_ = 0;
  uint64_t pending_ = 1;
  std::vector<uint8_t> out_;
};

class Decoder {
public:
  Decoder(const uint8_t* data, size_t n) : p_(data), end_(data + n) {
    for (int i = 0; i < 5; ++i) code_ = (code_ << 8) | next();
  }
  int bit(Prob& pr) {
    const uint32_t bound = (range_ >> kProbBits) * pr.p;
    int b;
    if (code_ < bound) {
      range_ = bound;
      pr.p = uint16_t(pr.p + (((1 << kProbBits) - pr.p) >> kAdapt));
      b = 0;
    } else {
      code_ -= bound;
      range_ -= bound;
      pr.p = uint16_t(pr.p - (pr.p >> kAdapt));
      b = 1;
    }
    while (range_ < kTop) {
      range_ <<= 8;
      code_ = (code_ << 8) | next();
    }
    return b;
  }
  bool overran() const { return overrun_ > 4; }

private:
  uint32_t next() {
    if (p_ < end_) return *p_++;
    ++overrun_;
    return 0;
  }
  const uint8_t *p_, *end_;
  uint32_t code_ = 0, range_ = 0xFFFFFFFFu;
  int overrun_ = 0;
};

// The models: zero flag by neighbourhood, sign by the x-1 sign, unary magnitude bits by position and
// neighbourhood size, gamma length and mantissa bits by position.
struct Models {
  Prob zero[4][4], sign[3], unary[kUnary][3], gamma_len[kMaxBits], gamma_bits[kMaxBits];
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
  Encoder enc;
  for_each_voxel(d, [&](int64_t x, int64_t y, int64_t z, int64_t i) {
    const Context c = context_of(q, d, x, y, z, i);
    const int32_t v = q[i];
    const int mag_ctx = c.size;
    enc.bit(m->zero[c.nonzero][c.mag], v != 0);
    if (v == 0) return;
    enc.bit(m->sign[c.sign], v < 0);
    const uint64_t a = uint64_t(std::abs(int64_t(v)));
    for (int k = 1; k <= kUnary; ++k) {
      enc.bit(m->unary[k - 1][mag_ctx], a > uint64_t(k));
      if (a == uint64_t(k)) return;
    }
    const uint64_t rest = a - kUnary;  // >= 1: Elias gamma, length then the bits below the top one
    int len = 0;
    while ((rest >> (len + 1)) != 0) ++len;
    for (int k = 0; k < len; ++k) enc.bit(m->gamma_len[k], 1);
    enc.bit(m->gamma_len[len], 0);
    for (int k = len - 1; k >= 0; --k) enc.bit(m->gamma_bits[k], int((rest >> k) & 1));
  });
  return enc.finish();
}

void context_decode(const uint8_t* data, size_t n, Int3 d, int32_t* q, const std::string& what) {
  auto m = std::make_unique<Models>();
  Decoder dec(data, n);
  for_each_voxel(d, [&](int64_t x, int64_t y, int64_t z, int64_t i) {
    const Context c = context_of(q, d, x, y, z, i);
    const int mag_ctx = c.size;
    if (!dec.bit(m->zero[c.nonzero][c.mag])) {
      q[i] = 0;
      return;
    }
    const bool negative = dec.bit(m->sign[c.sign]);
    uint64_t a = 0;
    for (int k = 1; k <= kUnary && a == 0; ++k)
      if (!dec.bit(m->unary[k - 1][mag_ctx])) a = uint64_t(k);
    if (a == 0) {
      int len = 0;
      while (dec.bit(m->gamma_len[len]))
        if (++len >= kMaxBits - 1) fail("{}: the residual block is corrupted (code too long)", what);
      uint64_t rest = 1;
      for (int k = len - 1; k >= 0; --k) rest = (rest << 1) | uint64_t(dec.bit(m->gamma_bits[k]));
      a = rest + kUnary;
    }
    if (a > uint64_t(INT32_MAX)) fail("{}: the residual block is corrupted (value out of range)", what);
    q[i] = negative ? -int32_t(a) : int32_t(a);
  });
  if (dec.overran()) fail("{}: the residual block is corrupted (truncated)", what);
}

}  // namespace vnr
