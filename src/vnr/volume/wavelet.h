#pragma once
// The CDF 9/7 wavelet (JPEG 2000's irreversible one) over a 3-D grid of any dims, by lifting with
// whole-sample symmetric extension, in place in the Mallat layout (each level's low band first along
// every axis it splits). Residual coding (docs/COMPRESSION.md) quantises its coefficients: the
// transform packs a smooth field's energy into few of them, as SPERR's and JPEG 2000's do.
#include <cstdint>
#include <vector>
#include "vnr/math.h"

namespace vnr {

// How many levels a grid of `dims` is split into: at each level every axis with at least
// kWaveletMinLength samples in the current low band is halved (rounding up), at most kWaveletMaxLevels.
constexpr int kWaveletMaxLevels = 5;
constexpr int64_t kWaveletMinLength = 8;
int wavelet_levels(Int3 dims);

// values: dims.count() values, x fastest; the forward transform of `levels` levels, in place. Each line
// is lifted in double precision and stored back as float (half the memory of a double field).
void wavelet_forward(std::vector<float>& values, Int3 dims, int levels);
// The inverse (the forward transform's inverse up to float rounding).
void wavelet_inverse(std::vector<float>& values, Int3 dims, int levels);
// The level of each coefficient of a `levels`-level transform of dims in the Mallat layout: 0 for the
// finest detail bands, up to levels - 1 for the coarsest, `levels` for the low band.
std::vector<uint8_t> wavelet_coefficient_levels(Int3 dims, int levels);

}  // namespace vnr
