#pragma once
// Context-adaptive binary arithmetic coding of a residual field (residual_context_coder.cpp).
#include <cstdint>
#include <string>
#include <vector>
#include "vnr/math.h"

namespace vnr {

// The largest magnitude the coder takes (its Elias-gamma codes stop at 30 bits).
constexpr int64_t kMaxContextMagnitude = int64_t(1) << 30;

// q: dims.count() values, x fastest, |q| <= kMaxContextMagnitude (else one error). `wavelet` (coefficients in the Mallat layout; a different stream,
// decoded with the same flag): in blocks of 8^3 flagged when non-zero, the contexts also seeing each
// value's parent at (x/2, y/2, z/2).
std::vector<uint8_t> context_encode(const int32_t* q, Int3 dims, bool wavelet = false);
// The inverse into q; a truncated or damaged stream fails naming `what` where it can tell (the caller
// checks a CRC of the values for the rest).
void context_decode(const uint8_t* data, size_t n, Int3 dims, int32_t* q, const std::string& what, bool wavelet = false);

}  // namespace vnr
