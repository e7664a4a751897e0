#include <gtest/gtest.h>
#include <cmath>
#include "vnr/dtype.h"
#include "vnr/error.h"
#include "vnr/core/half.h"
#include "vnr/progress.h"
#include "vnr/core/rng.h"

using namespace vnr;

// Vectors from docs/semantics.md A.10 (spot checks of tiny-cuda-nn's random numbers).
TEST(Rng, SeedSeqMatchesTcnn) { EXPECT_EQ(seed_seq_first_word(1337), 2150097757u); }

TEST(Rng, Pcg32FloatsMatchReference) {
  Pcg32 rng(2150097757u);
  const float expected[] = {0.114209533f, 0.911352873f, 0.565215945f, 0.816819549f};
  for (float e : expected) EXPECT_FLOAT_EQ(rng.next_float(), e);
}

TEST(Rng, AdvanceEqualsStepping) {
  Pcg32 a(42), b(42);
  for (int i = 0; i < 1000; ++i) a.next_uint();
  b.advance(1000);
  EXPECT_EQ(a.next_uint(), b.next_uint());
}

TEST(Half, RoundTripAndRounding) {
  EXPECT_EQ(float_to_half(1.0f), 0x3c00);
  EXPECT_EQ(float_to_half(-2.0f), 0xc000);
  EXPECT_EQ(float_to_half(65504.0f), 0x7bff);
  EXPECT_EQ(float_to_half(1e6f), 0x7c00);
  EXPECT_EQ(half_to_float(0x0001), std::ldexp(1.0f, -24));  // smallest subnormal
  EXPECT_EQ(float_to_half(std::ldexp(1.0f, -24)), 0x0001);
  // 1 + 2^-11 is exactly halfway between 1 and 1 + 2^-10: ties to even -> 1.
  EXPECT_EQ(float_to_half(1.0f + std::ldexp(1.0f, -11)), 0x3c00);
  EXPECT_EQ(float_to_half(1.0f + 3 * std::ldexp(1.0f, -11)), 0x3c02);
  for (uint32_t h = 0; h < 0x7c00; ++h) EXPECT_EQ(float_to_half(half_to_float(uint16_t(h))), h);
}

TEST(DType, ParseNamesAndErrors) {
  EXPECT_EQ(parse_dtype("UNSIGNED_SHORT"), DType::UInt16);
  EXPECT_EQ(parse_dtype("float"), DType::Float32);
  EXPECT_EQ(dtype_size(DType::Float64), 8u);
  try {
    parse_dtype("complex64");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("allowed: int8"), std::string::npos);
  }
}

// The first progress update of `vnr bench infer --device cuda` came after the CUDA context's start-up
// and extrapolated "ETA 967s" for a 3-second run: no estimate before 1 % of the work and half a second.
TEST(Progress, EtaIsWithheldUntilTheRateMeansSomething) {
  EXPECT_EQ(eta_text(0.001, 1.0), "ETA ?");   // 0.1 % done
  EXPECT_EQ(eta_text(0.2, 0.1), "ETA ?");     // too early
  EXPECT_EQ(eta_text(0.25, 3.0), "ETA 9s");   // 3 s for a quarter: 9 s left
  EXPECT_EQ(eta_text(0.5, 10.0), "ETA 10s");
  EXPECT_EQ(eta_text(1.0, 10.0), "ETA 0s");
  EXPECT_EQ(eta_text(1.5, 10.0), "ETA 0s");   // done beyond the total
}
