#pragma once
// Internal to the bf16 kernel files (mlp_bf16.cpp, mlp_bf16_train.cpp): the target attribute under
// which their AVX512-BF16 code is compiled (chosen at run time by bf16_supported(); Highway 1.0.3 has
// no vdpbf16ps target), and helpers both use.
#include <cstdint>

#include "vnr/nn/mlp_bf16.h"

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define VNR_HAVE_BF16_KERNELS 1
#define VNR_BF16_TARGET __attribute__((target("avx512f,avx512bw,avx512vl,avx512dq,avx512bf16")))
#else
#define VNR_HAVE_BF16_KERNELS 0
#endif

namespace vnr::kernels::bf16_detail {

inline float lo_of(uint32_t p) { return from_bf16(uint16_t(p & 0xffffu)); }
inline float hi_of(uint32_t p) { return from_bf16(uint16_t(p >> 16)); }

#if VNR_HAVE_BF16_KERNELS
// Word permutation that interleaves the two halves of vcvtne2ps2bf16's result (low 16 words: row r,
// high 16: row r + 1) into pairs: out word 2s = row r's sample s, 2s + 1 = row r + 1's.
alignas(64) inline constexpr int16_t kInterleave[32] = {0, 16, 1, 17, 2,  18, 3,  19, 4,  20, 5,  21, 6,  22, 7,  23,
                                                        8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31};

// 32-bit lane s = (bf16(lo[s]), bf16(hi[s])).
VNR_BF16_TARGET inline __m512i pack_pairs(__m512 lo, __m512 hi) {
  return _mm512_permutexvar_epi16(_mm512_load_si512(kInterleave), (__m512i)_mm512_cvtne2ps_pbh(hi, lo));
}
#endif

}  // namespace vnr::kernels::bf16_detail
