#pragma once
// An adaptive binary arithmetic coder (a carry-less range coder with 12-bit probabilities, LZMA
// style) and the magnitude binarization the context coders share: the residual field's
// (train/residual_context_coder.cpp) and the quantized parameters' (nn/param_context_coder.cpp).
#include <cstddef>
#include <cstdint>
#include <vector>

namespace vnr {

constexpr int kCoderProbBits = 12, kCoderAdapt = 5;

// The probability of a 0 bit, in 1/4096, moving 1/32 of the way towards each coded bit.
struct Prob {
  uint16_t p = 1 << (kCoderProbBits - 1);
  void update(int b) {
    if (b == 0) p = uint16_t(p + (((1 << kCoderProbBits) - p) >> kCoderAdapt));
    else p = uint16_t(p - (p >> kCoderAdapt));
  }
};

// A probability that learns fast first and then settles: the k-th update moves 1/2^min(k, 7) of the
// way (16-bit state), close to counting for a context's first bits and steady on long stationary
// streams (quantized parameters: 1.5-1 % smaller than Prob's fixed 1/32 on trained models).
struct CountingProb {
  uint16_t p = 1 << (kCoderProbBits - 1);
  uint16_t state = 1 << 15;
  uint8_t n = 0;
  void update(int b) {
    const int shift = n < 7 ? n + 1 : 7;
    if (n < 7) ++n;
    if (b == 0) state = uint16_t(state + ((65536 - state) >> shift));
    else state = uint16_t(state - (state >> shift));
    const int q = state >> (16 - kCoderProbBits);
    p = uint16_t(q < 1 ? 1 : q > (1 << kCoderProbBits) - 1 ? (1 << kCoderProbBits) - 1 : q);
  }
};

class BinaryEncoder {
public:
  template <class P>
  void bit(P& pr, int b) {
    const uint32_t bound = (range_ >> kCoderProbBits) * pr.p;
    if (b == 0) {
      range_ = bound;
    } else {
      low_ += bound;
      range_ -= bound;
    }
    pr.update(b);
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
  static constexpr uint32_t kTop = 1u << 24;
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

// Reads past the end as zero bytes; overran() says when that went beyond the encoder's flush, which
// only a truncated or damaged stream does.
class BinaryDecoder {
public:
  BinaryDecoder(const uint8_t* data, size_t n) : p_(data), end_(data + n) {
    for (int i = 0; i < 5; ++i) code_ = (code_ << 8) | next();
  }
  template <class P>
  int bit(P& pr) {
    const uint32_t bound = (range_ >> kCoderProbBits) * pr.p;
    int b = 0;
    if (code_ < bound) {
      range_ = bound;
    } else {
      code_ -= bound;
      range_ -= bound;
      b = 1;
    }
    pr.update(b);
    while (range_ < kTop) {
      range_ <<= 8;
      code_ = (code_ << 8) | next();
    }
    return b;
  }
  bool overran() const { return overrun_ > 4; }

private:
  static constexpr uint32_t kTop = 1u << 24;
  uint32_t next() {
    if (p_ < end_) return *p_++;
    ++overrun_;
    return 0;
  }
  const uint8_t *p_, *end_;
  uint32_t code_ = 0, range_ = 0xFFFFFFFFu;
  int overrun_ = 0;
};

// A magnitude a >= 1: unary up to kUnaryMagnitudes (bit k: a > k, one model each), then Elias gamma
// of a - kUnaryMagnitudes (length bits and mantissa bits, one model per position).
constexpr int kUnaryMagnitudes = 14;
constexpr int kMaxGammaBits = 31;  // a longer gamma code is corruption

template <class P = Prob>
struct MagnitudeModels {
  P unary[kUnaryMagnitudes];
};
template <class P = Prob>
struct GammaModels {
  P len[kMaxGammaBits], bits[kMaxGammaBits];
};

template <class P>
void encode_magnitude(BinaryEncoder& enc, MagnitudeModels<P>& m, GammaModels<P>& g, uint64_t a) {
  for (int k = 1; k <= kUnaryMagnitudes; ++k) {
    enc.bit(m.unary[k - 1], a > uint64_t(k));
    if (a == uint64_t(k)) return;
  }
  const uint64_t rest = a - kUnaryMagnitudes;
  int len = 0;
  while ((rest >> (len + 1)) != 0) ++len;
  for (int k = 0; k < len; ++k) enc.bit(g.len[k], 1);
  enc.bit(g.len[len], 0);
  for (int k = len - 1; k >= 0; --k) enc.bit(g.bits[k], int((rest >> k) & 1));
}

// The inverse; 0 when the gamma code runs longer than any encoder writes (corruption).
template <class P>
uint64_t decode_magnitude(BinaryDecoder& dec, MagnitudeModels<P>& m, GammaModels<P>& g) {
  for (int k = 1; k <= kUnaryMagnitudes; ++k)
    if (!dec.bit(m.unary[k - 1])) return uint64_t(k);
  int len = 0;
  while (dec.bit(g.len[len]))
    if (++len >= kMaxGammaBits - 1) return 0;
  uint64_t rest = 1;
  for (int k = len - 1; k >= 0; --k) rest = (rest << 1) | uint64_t(dec.bit(g.bits[k]));
  return rest + kUnaryMagnitudes;
}

}  // namespace vnr
