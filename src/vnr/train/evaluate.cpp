#include "vnr/train/evaluate.h"
#include "vnr/train/decoder.h"
#include <algorithm>
#include <chrono>
#include <cmath>
#include <vector>
#include "vnr/core/error.h"
#include "vnr/core/metrics.h"
#include "vnr/core/progress.h"
#include "vnr/core/rng.h"
#include "vnr/volume/raw_access.h"
#include "vnr/volume/stream.h"

namespace vnr {

namespace {

EvalResult evaluate_with(Decoder& decoder, const Volume& vol, bool with_ssim) {
  EvalResult r;
  std::vector<float> dec(vol.data.size());
  auto t0 = std::chrono::steady_clock::now();
  decoder.slices(vol.dims, 0, vol.dims.z, dec.data());
  r.decode_seconds = seconds_since(t0);
  ErrorStats e = error_stats(vol.data.data(), dec.data(), vol.dims);
  r.psnr = e.psnr;
  r.mse = e.mse;
  r.max_abs_error = e.max_abs_error;
  r.max_abs_error_original = e.max_abs_error * (vol.hi - vol.lo);
  if (with_ssim) r.ssim = ssim3d(vol.data.data(), dec.data(), vol.dims);
  return r;
}

double psnr_of_mse(double mse) { return mse > 0 ? 10 * std::log10(1 / mse) : 999.0; }  // error_stats' convention
EvalResult streamed_with(Decoder& decoder, const VolumeDesc& desc, double lo, double hi, const LoadOptions& opts,
                         bool with_ssim, const std::function<void(double)>& progress, int64_t slab_voxels) {
  const Int3 d = desc.dims;
  if (d.x <= 0 || d.y <= 0 || d.z <= 0) fail("'{}': invalid dims", desc.path);
  const int64_t slice = d.x * d.y, nz = d.z;
  if (slab_voxels <= 0) slab_voxels = int64_t(1) << 24;
  const int64_t slab_slices = std::clamp<int64_t>(slab_voxels / slice, 1, nz);
  // ssim3d's window: 7 voxels per axis, or the whole axis when shorter.
  const int64_t wx = std::min<int64_t>(7, d.x), wy = std::min<int64_t>(7, d.y), wz = std::min<int64_t>(7, nz);
  const double windows_per_slice = double((d.x - wx + 1) * (d.y - wy + 1));
  // With SSIM, the last wz - 1 slices stay in front of the next slab, so that windows crossing the
  // slab boundary are counted once and see the same voxels as in the whole volume.
  const int64_t keep = with_ssim ? wz - 1 : 0;
  std::vector<float> ref, dec;
  try {
    if (with_ssim) ref.resize(size_t((keep + slab_slices) * slice));
    dec.resize(size_t((keep + slab_slices) * slice));
  } catch (const std::bad_alloc&) {
    fail("cannot allocate {:.1f} MiB of slab buffers to evaluate '{}'",
         double((keep + slab_slices) * slice) * 8 / (1 << 20), desc.path);
  }

  EvalResult r;
  double se = 0, ssim_sum = 0;
  int64_t held = 0;  // slices in ref/dec (SSIM only keeps slices across slabs)
  for_each_slab(desc, lo, hi, opts, slab_slices * slice, [&](int64_t z0, int64_t k, const float* values) {
    float* rs = nullptr;
    if (with_ssim) {
      rs = ref.data() + held * slice;
      std::copy(values, values + k * slice, rs);
    }
    const float* reference = with_ssim ? rs : values;
    float* decoded = dec.data() + held * slice;
    auto t0 = std::chrono::steady_clock::now();
    decoder.slices(d, z0, z0 + k, decoded);
    r.decode_seconds += seconds_since(t0);
    ErrorStats e = error_stats(reference, decoded, Int3{d.x, d.y, k});
    se += e.mse * double(k * slice);
    r.max_abs_error = std::max(r.max_abs_error, e.max_abs_error);
    if (with_ssim) {
      held += k;
      if (held >= wz) {  // windows starting at buffer slices 0 .. held - wz are complete
        ssim_sum += ssim3d(ref.data(), dec.data(), Int3{d.x, d.y, held}) * windows_per_slice * double(held - wz + 1);
        std::copy(ref.begin() + (held - keep) * slice, ref.begin() + held * slice, ref.begin());
        std::copy(dec.begin() + (held - keep) * slice, dec.begin() + held * slice, dec.begin());
        held = keep;
      }
    }
    if (progress) progress(double(z0 + k) / double(nz));
  });
  r.mse = se / double(d.count());
  r.psnr = psnr_of_mse(r.mse);
  r.max_abs_error_original = r.max_abs_error * (hi - lo);
  if (with_ssim) r.ssim = ssim_sum / (windows_per_slice * double(nz - wz + 1));
  return r;
}

SampledEval sampled_with(Decoder& decoder, const VolumeDesc& desc, double lo, double hi, int64_t n_samples,
                         uint64_t seed, const LoadOptions& opts) {
  if (n_samples <= 0) fail("the number of samples must be positive, got {}", n_samples);
  const RawVolumeFile file(desc, lo, hi, opts.non_finite, "sampled evaluation",
                           "evaluating without --sample streams gzip data");
  const uint64_t n_voxels = desc.dims.count();
  // Fixed batches: memory stays bounded and the draws do not depend on the thread count.
  const int64_t batch = std::min<int64_t>(n_samples, int64_t(1) << 20);
  std::vector<int64_t> idx(static_cast<size_t>(batch));
  std::vector<float> truth(static_cast<size_t>(batch)), decoded(static_cast<size_t>(batch));
  Pcg32 rng(seed, 0x9e3779b97f4a7c15ULL);
  SampledEval s;
  double mean = 0, m2 = 0;  // Welford: mean and summed squared deviation of the squared errors
  for (int64_t done = 0; done < n_samples;) {
    const int64_t m = std::min(batch, n_samples - done);
    for (int64_t i = 0; i < m; ++i) {
      uint64_t r = (uint64_t(rng.next_uint()) << 32) | rng.next_uint();
      idx[size_t(i)] = int64_t(r % n_voxels);  // modulo bias <= n_voxels / 2^64: negligible
    }
    file.read_voxels(idx.data(), m, truth.data());
    auto t0 = std::chrono::steady_clock::now();
    decoder.voxels(desc.dims, idx.data(), m, decoded.data());
    s.decode_seconds += seconds_since(t0);
    for (int64_t i = 0; i < m; ++i) {
      double diff = double(decoded[size_t(i)]) - double(truth[size_t(i)]);
      double sq = diff * diff;
      double delta = sq - mean;
      mean += delta / double(done + i + 1);
      m2 += delta * (sq - mean);
      s.max_abs_error = std::max(s.max_abs_error, std::fabs(diff));
    }
    done += m;
  }
  s.samples = n_samples;
  s.mse = mean;
  s.mse_stderr = n_samples > 1 ? std::sqrt(m2 / double(n_samples - 1) / double(n_samples)) : 0.0;
  constexpr double z95 = 1.959963984540054;  // two-sided 95% normal quantile
  s.psnr = psnr_of_mse(s.mse);
  s.psnr_ci95_lo = psnr_of_mse(s.mse + z95 * s.mse_stderr);  // more error, lower PSNR
  s.psnr_ci95_hi = psnr_of_mse(s.mse - z95 * s.mse_stderr);
  s.max_abs_error_original = s.max_abs_error * (hi - lo);
  return s;
}

}  // namespace

// Every evaluation runs through a Decoder: of a network, or of a model (multi-brick models blend bricks).
EvalResult evaluate(const Network& net, const Volume& vol, bool with_ssim, Device device, const Residuals* residuals) {
  Decoder d(net, device, residuals);
  return evaluate_with(d, vol, with_ssim);
}
EvalResult evaluate(const Model& model, const Volume& vol, bool with_ssim, Device device) {
  Decoder d(model, device);
  return evaluate_with(d, vol, with_ssim);
}
EvalResult evaluate_streamed(const Network& net, const VolumeDesc& desc, double lo, double hi, const LoadOptions& opts,
                             bool with_ssim, const std::function<void(double)>& progress, int64_t slab_voxels,
                             Device device, const Residuals* residuals) {
  Decoder d(net, device, residuals);
  return streamed_with(d, desc, lo, hi, opts, with_ssim, progress, slab_voxels);
}
EvalResult evaluate_streamed(const Model& model, const VolumeDesc& desc, double lo, double hi, const LoadOptions& opts,
                             bool with_ssim, const std::function<void(double)>& progress, int64_t slab_voxels,
                             Device device) {
  Decoder d(model, device);
  return streamed_with(d, desc, lo, hi, opts, with_ssim, progress, slab_voxels);
}
SampledEval evaluate_sampled(const Network& net, const VolumeDesc& desc, double lo, double hi, int64_t n_samples,
                             uint64_t seed, const LoadOptions& opts, Device device, const Residuals* residuals) {
  Decoder d(net, device, residuals);
  return sampled_with(d, desc, lo, hi, n_samples, seed, opts);
}
SampledEval evaluate_sampled(const Model& model, const VolumeDesc& desc, double lo, double hi, int64_t n_samples,
                             uint64_t seed, const LoadOptions& opts, Device device) {
  Decoder d(model, device);
  return sampled_with(d, desc, lo, hi, n_samples, seed, opts);
}

}  // namespace vnr
