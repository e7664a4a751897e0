#pragma once
// Context-adaptive binary arithmetic coding of a residual field (residual_context_coder.cpp).
#include <cstdint>
#include <string>
#include <vector>
#include "vnr/core/math.h"

namespace vnr {

// q: dims.count() values, x fastest.
std::vector<uint8_t> context_encode(const int32_t* q, Int3 dims);
// The inverse into q; a truncated or damaged stream fails naming `what` where it can tell (the caller
// checks a CRC of the values for the rest).
void context_decode(const uint8_t* data, size_t n, Int3 dims, int32_t* q, const std::string& what);

}  // namespace vnr
