#pragma once
// Rate-distortion benchmark (`vnr bench rd`, docs/COMPRESSION.md): vnr's models at several compression
// ratios and error bounds, side by side with ZFP (Debian's libzfp, fixed rate and fixed accuracy) on
// the same volume in the same run. PSNR is vnr's: 10 log10(1 / MSE) over every voxel in normalised
// units (= 20 log10(range) - 10 log10(MSE) in data units); ratio = source bytes / compressed bytes.
#include <cstdint>
#include <functional>
#include <string>
#include <vector>
#include "vnr/json.h"
#include "vnr/volume.h"

namespace vnr {

struct RdPoint {
  std::string codec;     // "vnr", "vnr-bound", "vnr-time", "zfp-rate", "zfp-accuracy"
  double parameter = 0;  // target ratio, relative bound, training budget (s), bits per value, or tolerance
  uint64_t bytes = 0;    // compressed size
  double ratio = 0, psnr = 0;
  double max_abs_error = 0;  // data units
  double seconds = 0;        // compression (vnr: training + residuals)
  Json extra;                // codec-specific details (vnr-bound: residual bytes, non-zero fraction...)
};

// ZFP over the volume in data units as float32 (integer volumes as float copies; the ratio counts the
// source dtype's bytes, as the peers' figures do). Fixed rate: bits per value; fixed accuracy: an
// absolute tolerance in data units.
RdPoint zfp_fixed_rate(const Volume& volume, double bits_per_value);
RdPoint zfp_fixed_accuracy(const Volume& volume, double tolerance);

struct RdOptions {
  std::vector<double> ratios{8, 16, 32, 64, 128, 256, 512};  // vnr --target-ratio points
  std::vector<double> rel_bounds{1e-2, 1e-3};                 // vnr-bound and zfp-accuracy points
  std::vector<double> zfp_rates{0.5, 1, 2, 4, 8};              // bits per value
  double seconds = 60;                                          // training time per vnr model
  // PSNR against training time: models at time_ratio trained for each of these budgets (seconds), from
  // scratch each (the cool-down follows the budget); none by default.
  std::vector<double> times;
  double time_ratio = 64;
  int64_t steps = -1;                                           // > 0: steps instead of seconds
  std::string config = "auto";
  std::string residuals = "auto";  // the --target-ratio points' --residuals
  std::string device = "auto";
  uint32_t seed = 1337;
  std::function<void(const std::string& line)> message;        // a line per point as it is measured
};

struct RdReport {
  std::string volume;
  Int3 dims;
  uint64_t volume_bytes = 0;
  std::vector<RdPoint> points;
  Json to_json() const;
};

// Every vnr model trained once per ratio; each error bound is then met on each of those networks with
// residuals and the smallest total kept (the network that is the best predictor at that bound).
RdReport run_rate_distortion(const std::string& volume_path, const Volume& volume, const RdOptions& options);

}  // namespace vnr
