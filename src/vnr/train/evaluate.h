#pragma once
// Evaluation of a network against its volume: in memory, streamed in slabs, or sampled.
#include <cstdint>
#include <functional>
#include <vector>
#include "vnr/core/brick_box.h"
#include "vnr/device.h"
#include "vnr/model.h"
#include "vnr/nn/network.h"
#include "vnr/train/residuals.h"
#include "vnr/volume/volume.h"

namespace vnr {

class RawVolumeFile;  // volume/raw_access.h

EvalResult evaluate(const Network& net, const Volume& vol, bool with_ssim = true, Device device = Device::Cpu,
                    const Residuals* residuals = nullptr);
// A model's evaluation applies its residuals (error-bound models) and blends its bricks (multi-brick).
// The overloads taking a Model decode a multi-brick model blended (train/bricks.h).
EvalResult evaluate(const Model& model, const Volume& vol, bool with_ssim = true, Device device = Device::Cpu);

// evaluate() for a volume that is not in memory: the volume (desc, normalised with [lo, hi] as
// load_volume would) is streamed in z-slabs of about slab_voxels voxels (0: 16 M voxels, i.e.
// 64 MiB per copy; at least one slice) and the network is decoded slab by slab. Memory: two
// slab-sized float arrays (the volume as read, the network's values); with SSIM a third, and
// 6 slices of overlap. PSNR, MSE and max error match evaluate() on the loaded volume up to the
// order of a double sum; the SSIM is the same mean over every 7x7x7 window (windows crossing a
// slab boundary see the 6 slices before it), equal to ssim3d's up to rounding (~1e-14).
// `progress` gets the fraction of slices done.
EvalResult evaluate_streamed(const Network& net, const VolumeDesc& desc, double lo, double hi,
                             const LoadOptions& opts, bool with_ssim = true,
                             const std::function<void(double fraction)>& progress = {}, int64_t slab_voxels = 0,
                             Device device = Device::Cpu, const Residuals* residuals = nullptr);
EvalResult evaluate_streamed(const Model& model, const VolumeDesc& desc, double lo, double hi,
                             const LoadOptions& opts, bool with_ssim = true,
                             const std::function<void(double fraction)>& progress = {}, int64_t slab_voxels = 0,
                             Device device = Device::Cpu);

// PSNR of an MSE of normalised values (range 1): 10 log10(1 / mse), 999 for mse <= 0 (error_stats').
double psnr_of_mse(double mse);

// The network decoded on a grid of box.size() voxels (a brick's network on its box), its output slices [z_begin, z_end),
// against the voxels of box in truth, read in z-slabs of about slab_voxels (0: 16 M) as
// evaluate_streamed reads. Errors are those slices'; with SSIM, the windows whose first slice is among
// them (the 6 slices past z_end are read and decoded for them). Over all slices of the box, the result
// is evaluate() on the box loaded, up to the order of the sums.
EvalSums evaluate_box_slices(const Network& net, const RawVolumeFile& truth, const Box3& box, int64_t z_begin,
                             int64_t z_end, bool with_ssim, int64_t slab_voxels = 0, Device device = Device::Cpu);

// A multi-brick model's part of its evaluation against truth (the volume at the model's grid): the errors
// of the voxels in region and, with SSIM, the windows whose first voxel is in it (reading and decoding up
// to 6 voxels past it). Regions that tile the volume (the bricks' owned boxes: MPI ranks) add up to
// the whole evaluation; the model needs the bricks touching region grown by 7 voxels loaded.
EvalSums evaluate_region(const Model& model, const RawVolumeFile& truth, const Box3& region, bool with_ssim,
                         int64_t slab_voxels = 0);

// PSNR estimated from n_samples voxels drawn uniformly (with replacement; deterministic for a
// seed), read with RawVolumeFile (uncompressed data only) and decoded as evaluate() decodes them.
// The 95% interval is the normal interval mean +- 1.96 standard errors of the per-voxel squared
// error, mapped through PSNR = 10 log10(1/MSE) (an interval end at MSE <= 0 is reported as 999).
// Memory: O(min(n_samples, 1 M)).
struct SampledEval {
  double psnr = 0;                        // from the sampled MSE
  double psnr_ci95_lo = 0, psnr_ci95_hi = 0;
  double mse = 0, mse_stderr = 0;         // normalised units
  double max_abs_error = 0;               // largest error among the samples, normalised units
  double max_abs_error_original = 0;      // the same in original units
  int64_t samples = 0;
  double decode_seconds = 0;
};
SampledEval evaluate_sampled(const Network& net, const VolumeDesc& desc, double lo, double hi, int64_t n_samples,
                             uint64_t seed, const LoadOptions& opts = {}, Device device = Device::Cpu,
                             const Residuals* residuals = nullptr);
SampledEval evaluate_sampled(const Model& model, const VolumeDesc& desc, double lo, double hi, int64_t n_samples,
                             uint64_t seed, const LoadOptions& opts = {}, Device device = Device::Cpu);

}  // namespace vnr
