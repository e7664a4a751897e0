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

// fn(z0, k, values): consecutive slabs of the reference slices [z_first, z_last), at most slab_slices each.
using SlabFn = std::function<void(int64_t z0, int64_t k, const float* values)>;
using SlabSource = std::function<void(int64_t z_first, int64_t z_last, int64_t slab_slices, const SlabFn& fn)>;

// The sums of the output slices [z_begin, z_end) of grid d: errors of those slices, and with SSIM the
// 7x7x7 windows whose first slice is among them (reading up to wz - 1 slices past z_end). The last
// wz - 1 slices of a slab stay in front of the next, so that windows crossing a slab boundary are
// counted once and see the same voxels as in the whole volume.
// `what` names the data in messages.
EvalSums sums_with(Decoder& decoder, Int3 d, int64_t z_begin, int64_t z_end, bool with_ssim, int64_t slab_voxels,
                   const SlabSource& source, const std::function<void(double)>& progress, const std::string& what) {
  if (d.x <= 0 || d.y <= 0 || d.z <= 0) fail("evaluation of an empty {}x{}x{} grid", d.x, d.y, d.z);
  if (z_begin < 0 || z_end > d.z || z_begin > z_end) fail("slices [{}, {}) are not in 0..{}", z_begin, z_end, d.z);
  EvalSums r;
  if (z_begin == z_end) return r;
  const int64_t slice = d.x * d.y;
  if (slab_voxels <= 0) slab_voxels = int64_t(1) << 24;
  // ssim3d's window: 7 voxels per axis, or the whole axis when shorter.
  const int64_t wx = std::min<int64_t>(7, d.x), wy = std::min<int64_t>(7, d.y), wz = std::min<int64_t>(7, d.z);
  const double windows_per_slice = double((d.x - wx + 1) * (d.y - wy + 1));
  const int64_t z_last = with_ssim ? std::min(d.z, z_end + wz - 1) : z_end;  // slices read: [z_begin, z_last)
  const int64_t slab_slices = std::clamp<int64_t>(slab_voxels / slice, 1, z_last - z_begin);
  const int64_t keep = with_ssim ? wz - 1 : 0;
  std::vector<float> ref, dec;
  try {
    if (with_ssim) ref.resize(size_t((keep + slab_slices) * slice));
    dec.resize(size_t((keep + slab_slices) * slice));
  } catch (const std::bad_alloc&) {
    fail("cannot allocate {:.1f} MiB of slab buffers to evaluate {}", double((keep + slab_slices) * slice) * 8 / (1 << 20),
         what);
  }
  int64_t held = 0;  // slices in ref/dec (SSIM only keeps slices across slabs)
  source(z_begin, z_last, slab_slices, [&](int64_t z0, int64_t k, const float* values) {
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
    const int64_t k_own = std::clamp<int64_t>(z_end - z0, 0, k);  // slices past z_end serve SSIM windows only
    if (k_own > 0) {
      const ErrorStats e = error_stats(reference, decoded, Int3{d.x, d.y, k_own});
      r.sse += e.mse * double(k_own * slice);
      r.voxels += k_own * slice;
      r.max_abs_error = std::max(r.max_abs_error, e.max_abs_error);
    }
    if (with_ssim) {
      held += k;
      if (held >= wz) {  // windows starting at buffer slices 0 .. held - wz are complete
        const double n = windows_per_slice * double(held - wz + 1);
        r.ssim_sum += ssim3d(ref.data(), dec.data(), Int3{d.x, d.y, held}) * n;
        r.ssim_windows += int64_t(n);
        std::copy(ref.begin() + (held - keep) * slice, ref.begin() + held * slice, ref.begin());
        std::copy(dec.begin() + (held - keep) * slice, dec.begin() + held * slice, dec.begin());
        held = keep;
      }
    }
    if (progress) progress(double(z0 + k - z_begin) / double(z_last - z_begin));
  });
  return r;
}

// Slabs of the box of `file`, read with pread.
SlabSource box_slabs(const RawVolumeFile& file, const Box3& box) {
  return [&file, box](int64_t z_first, int64_t z_last, int64_t slab_slices, const SlabFn& fn) {
    const Int3 d = box.size();
    std::vector<float> values(size_t(d.x * d.y * slab_slices));
    std::vector<unsigned char> scratch(file.scratch_bytes(Int3{d.x, d.y, slab_slices}));
    for (int64_t z0 = z_first; z0 < z_last; z0 += slab_slices) {
      const int64_t k = std::min(slab_slices, z_last - z0);
      file.read_box(Int3{box.lo.x, box.lo.y, box.lo.z + z0}, Int3{d.x, d.y, k}, values.data(), scratch.data());
      fn(z0, k, values.data());
    }
  };
}

EvalSums box_sums_with(Decoder& decoder, const RawVolumeFile& truth, const Box3& box, int64_t z_begin, int64_t z_end,
                       bool with_ssim, int64_t slab_voxels) {
  if (box.empty() || !(intersect(box, Box3{{0, 0, 0}, truth.dims()}) == box))
    fail("evaluation box [{}, {}) x [{}, {}) x [{}, {}) is empty or not inside the {}x{}x{} volume", box.lo.x, box.hi.x,
         box.lo.y, box.hi.y, box.lo.z, box.hi.z, truth.dims().x, truth.dims().y, truth.dims().z);
  return sums_with(decoder, box.size(), z_begin, z_end, with_ssim, slab_voxels, box_slabs(truth, box), {},
                   fmt::format("a box of '{}'", truth.desc().path));
}

EvalResult streamed_with(Decoder& decoder, const VolumeDesc& desc, double lo, double hi, const LoadOptions& opts,
                         bool with_ssim, const std::function<void(double)>& progress, int64_t slab_voxels) {
  const Int3 d = desc.dims;
  if (d.x <= 0 || d.y <= 0 || d.z <= 0) fail("'{}': invalid dims", desc.path);
  // for_each_slab streams the whole file (compressed too) from its first slice.
  const SlabSource whole_file = [&](int64_t, int64_t, int64_t slab_slices, const SlabFn& fn) {
    for_each_slab(desc, lo, hi, opts, slab_slices * d.x * d.y, fn);
  };
  return sums_with(decoder, d, 0, d.z, with_ssim, slab_voxels, whole_file, progress, fmt::format("'{}'", desc.path))
      .result(hi - lo);
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
EvalSums evaluate_box_slices(const Network& net, const RawVolumeFile& truth, const Box3& box, int64_t z_begin,
                             int64_t z_end, bool with_ssim, int64_t slab_voxels, Device device) {
  Decoder d(net, device);
  return box_sums_with(d, truth, box, z_begin, z_end, with_ssim, slab_voxels);
}
EvalSums evaluate_box_slices(const Model& model, const RawVolumeFile& truth, const Box3& box, int64_t z_begin,
                             int64_t z_end, bool with_ssim, int64_t slab_voxels, Device device) {
  Decoder d(model, device);
  return box_sums_with(d, truth, box, z_begin, z_end, with_ssim, slab_voxels);
}

void EvalSums::add(const EvalSums& o) {
  sse += o.sse;
  voxels += o.voxels;
  max_abs_error = std::max(max_abs_error, o.max_abs_error);
  ssim_sum += o.ssim_sum;
  ssim_windows += o.ssim_windows;
  decode_seconds += o.decode_seconds;
}

EvalResult EvalSums::result(double value_range) const {
  EvalResult r;
  r.mse = voxels > 0 ? sse / double(voxels) : 0.0;
  r.psnr = psnr_of_mse(r.mse);
  r.max_abs_error = max_abs_error;
  r.max_abs_error_original = max_abs_error * value_range;
  r.ssim = ssim_windows > 0 ? ssim_sum / double(ssim_windows) : 0.0;
  r.decode_seconds = decode_seconds;
  return r;
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
