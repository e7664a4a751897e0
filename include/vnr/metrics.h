#pragma once
#include <cstdint>
#include "vnr/math.h"

namespace vnr {

// Metrics in normalised units (docs/semantics.md B.4), over two x-fastest grids of the same dims.
struct ErrorStats {
  double mse = 0;
  double psnr = 0;           // 10 log10(1/mse); +inf reported as 999 when mse == 0
  double max_abs_error = 0;  // normalised units
};
ErrorStats error_stats(const float* reference, const float* test, Int3 dims);

// Mean 3-D SSIM, uniform 7x7x7 window, K1 = 0.01, K2 = 0.03, data range 1, sample covariance
// (n - 1), averaged over all windows fully inside the volume. Volumes smaller than 7 on an axis
// use the whole axis as the window.
double ssim3d(const float* reference, const float* test, Int3 dims);

}  // namespace vnr
