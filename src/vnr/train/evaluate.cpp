#include "vnr/train/evaluate.h"
#include "vnr/train/decoder.h"
#include "vnr/train/bricks.h"
#include <algorithm>
#include <chrono>
#include <cmath>
#include <vector>
#include "vnr/error.h"
#include "vnr/metrics.h"
#include "vnr/progress.h"
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

// fn(z0, k, values): consecutive slabs of the reference slices [z_first, z_last), at most slab_slices each.
using SlabFn = std::function<void(int64_t z0, int64_t k, const float* values)>;
using SlabSource = std::function<void(int64_t z_first, int64_t z_last, int64_t slab_slices, const SlabFn& fn)>;
// decode(z0, k, out): the evaluated field at slices [z0, z0 + k) of the slab grid.
using SlabDecode = std::function<void(int64_t z0, int64_t k, float* out)>;

// What sums_with evaluates: slabs of a grid g (whole x-y slices), of which the voxels [0, own.x) x
// [0, own.y) x [z_begin, z_end) count. With SSIM, the windows (of w voxels, the whole volume's
// window) whose first voxel is among them: g reaches w - 1 voxels past own in x and y (or ends with the
// volume), and up to w.z - 1 slices past z_end are read for them.
struct SlabGrid {
  Int3 g, own, w;
  int64_t z_begin = 0, z_end = 0;
};
// ssim3d's window on a volume of dims d: 7 voxels per axis, or the whole axis when shorter.
Int3 ssim_window(Int3 d) { return Int3{std::min<int64_t>(7, d.x), std::min<int64_t>(7, d.y), std::min<int64_t>(7, d.z)}; }

// Squared errors and the largest error over the first own_x x own_y voxels of k slices of a gx x gy grid.
void add_errors(const float* ref, const float* dec, int64_t gx, int64_t gy, int64_t k, int64_t own_x, int64_t own_y,
                EvalSums& r) {
  if (own_x == gx && own_y == gy) {
    const ErrorStats e = error_stats(ref, dec, Int3{gx, gy, k});
    r.sse += e.mse * double(gx * gy * k);
    r.max_abs_error = std::max(r.max_abs_error, e.max_abs_error);
  } else {
    for (int64_t z = 0; z < k; ++z)
      for (int64_t y = 0; y < own_y; ++y) {
        const int64_t row = (z * gy + y) * gx;
        for (int64_t x = 0; x < own_x; ++x) {
          const double d = double(dec[row + x]) - double(ref[row + x]);
          r.sse += d * d;
          r.max_abs_error = std::max(r.max_abs_error, std::fabs(d));
        }
      }
  }
  r.voxels += own_x * own_y * k;
}

// The last w.z - 1 slices of a slab stay in front of the next, so that windows crossing a slab boundary
// are counted once and see the same voxels as in the whole volume. `what` names the data in messages.
EvalSums sums_with(const SlabGrid& s, const SlabDecode& decode, bool with_ssim, int64_t slab_voxels,
                   const SlabSource& source, const std::function<void(double)>& progress, const std::string& what) {
  const Int3 g = s.g;
  if (g.x <= 0 || g.y <= 0 || g.z <= 0) fail("{}: cannot evaluate an empty {}x{}x{} grid", what, g.x, g.y, g.z);
  if (s.z_begin < 0 || s.z_end > g.z || s.z_begin > s.z_end) fail("slices [{}, {}) are not in 0..{}", s.z_begin, s.z_end, g.z);
  EvalSums r;
  if (s.z_begin == s.z_end || s.own.x <= 0 || s.own.y <= 0) return r;
  const int64_t slice = g.x * g.y;
  if (slab_voxels <= 0) slab_voxels = int64_t(1) << 24;
  // No window starts in the owned part when the grid ends less than a window past its start.
  with_ssim = with_ssim && g.x >= s.w.x && g.y >= s.w.y;
  const int64_t wz = s.w.z;
  const double windows_per_slice = double((g.x - s.w.x + 1) * (g.y - s.w.y + 1));
  const int64_t z_last = with_ssim ? std::min(g.z, s.z_end + wz - 1) : s.z_end;  // slices read: [z_begin, z_last)
  const int64_t slab_slices = std::clamp<int64_t>(slab_voxels / slice, 1, z_last - s.z_begin);
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
  source(s.z_begin, z_last, slab_slices, [&](int64_t z0, int64_t k, const float* values) {
    float* rs = nullptr;
    if (with_ssim) {
      rs = ref.data() + held * slice;
      std::copy(values, values + k * slice, rs);
    }
    const float* reference = with_ssim ? rs : values;
    float* decoded = dec.data() + held * slice;
    auto t0 = std::chrono::steady_clock::now();
    decode(z0, k, decoded);
    r.decode_seconds += seconds_since(t0);
    const int64_t k_own = std::clamp<int64_t>(s.z_end - z0, 0, k);  // slices past z_end serve SSIM windows only
    if (k_own > 0) add_errors(reference, decoded, g.x, g.y, k_own, s.own.x, s.own.y, r);
    if (with_ssim) {
      held += k;
      if (held >= wz) {  // windows starting at buffer slices 0 .. held - wz are complete
        const double n = windows_per_slice * double(held - wz + 1);
        r.ssim_sum += ssim3d(ref.data(), dec.data(), Int3{g.x, g.y, held}) * n;
        r.ssim_windows += int64_t(n);
        std::copy(ref.begin() + (held - keep) * slice, ref.begin() + held * slice, ref.begin());
        std::copy(dec.begin() + (held - keep) * slice, dec.begin() + held * slice, dec.begin());
        held = keep;
      }
    }
    if (progress) progress(double(z0 + k - s.z_begin) / double(z_last - s.z_begin));
  });
  return r;
}

// Slices [z0, z0 + k) of a whole-grid decode by `decoder`.
SlabDecode slices_of(Decoder& decoder, Int3 d) {
  return [&decoder, d](int64_t z0, int64_t k, float* out) { decoder.slices(d, z0, z0 + k, out); };
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

void check_box_in(const RawVolumeFile& truth, const Box3& box) {
  if (box.empty() || !(intersect(box, Box3{{0, 0, 0}, truth.dims()}) == box))
    fail("evaluation box [{}, {}) x [{}, {}) x [{}, {}) is empty or not inside the {}x{}x{} volume", box.lo.x, box.hi.x,
         box.lo.y, box.hi.y, box.lo.z, box.hi.z, truth.dims().x, truth.dims().y, truth.dims().z);
}

EvalSums box_sums_with(Decoder& decoder, const RawVolumeFile& truth, const Box3& box, int64_t z_begin, int64_t z_end,
                       bool with_ssim, int64_t slab_voxels) {
  check_box_in(truth, box);
  const Int3 g = box.size();
  const SlabGrid s{g, g, ssim_window(g), z_begin, z_end};
  return sums_with(s, slices_of(decoder, g), with_ssim, slab_voxels, box_slabs(truth, box), {},
                   fmt::format("a box of '{}'", truth.desc().path));
}

EvalResult streamed_with(Decoder& decoder, const VolumeDesc& desc, double lo, double hi, const LoadOptions& opts,
                         bool with_ssim, const std::function<void(double)>& progress, int64_t slab_voxels) {
  const Int3 d = desc.dims;
  // for_each_slab streams the whole file (compressed too) from its first slice.
  const SlabSource whole_file = [&](int64_t, int64_t, int64_t slab_slices, const SlabFn& fn) {
    for_each_slab(desc, lo, hi, opts, slab_slices * d.x * d.y, fn);
  };
  const SlabGrid s{d, d, ssim_window(d), 0, d.z};
  return sums_with(s, slices_of(decoder, d), with_ssim, slab_voxels, whole_file, progress,
                   fmt::format("'{}'", desc.path))
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
double psnr_of_mse(double mse) { return mse > 0 ? 10 * std::log10(1 / mse) : 999.0; }  // error_stats' convention

EvalSums evaluate_box_slices(const Network& net, const RawVolumeFile& truth, const Box3& box, int64_t z_begin,
                             int64_t z_end, bool with_ssim, int64_t slab_voxels, Device device) {
  Decoder d(net, device);
  return box_sums_with(d, truth, box, z_begin, z_end, with_ssim, slab_voxels);
}

EvalSums evaluate_region(const Model& model, const RawVolumeFile& truth, const Box3& region, bool with_ssim,
                         int64_t slab_voxels) {
  if (!model.bricks) fail("evaluate_region needs a multi-brick model");
  check_box_in(truth, region);
  const Int3 d = truth.dims(), w = ssim_window(d);
  if (!(model.bricks->plan.dims == d))
    fail("'{}' has {}x{}x{} voxels but the model {}x{}x{}", truth.desc().path, d.x, d.y, d.z, model.bricks->plan.dims.x,
         model.bricks->plan.dims.y, model.bricks->plan.dims.z);
  // The grid reaches w - 1 voxels past the region in x and y for the windows starting in it.
  Box3 ext = region;
  for (int a = 0; a < 2; ++a) ext.hi[a] = with_ssim ? std::min(d[a], region.hi[a] + w[a] - 1) : region.hi[a];
  ext.hi.z = d.z;  // sums_with reads past z_end only what SSIM needs
  const Int3 g = ext.size();
  const BrickedModel& m = *model.bricks;
  const SlabDecode decode = [&](int64_t z0, int64_t k, float* out) {
    decode_bricked_region(m, d, Box3{{ext.lo.x, ext.lo.y, ext.lo.z + z0}, {ext.hi.x, ext.hi.y, ext.lo.z + z0 + k}}, out);
  };
  const SlabGrid s{g, region.size(), w, 0, region.size().z};
  return sums_with(s, decode, with_ssim, slab_voxels, box_slabs(truth, ext), {},
                   fmt::format("a region of '{}'", truth.desc().path));
}

EvalSums evaluate_regions(const Model& model, const VolumeDesc& desc, ValueRange range, NonFinitePolicy policy,
                          const std::vector<Box3>& regions, bool with_ssim) {
  const RawVolumeFile file(desc, range.lo, range.hi, policy, "distributed evaluation",
                           "convert the volume to raw or NRRD (uncompressed)");
  EvalSums sums;
  for (const Box3& region : regions) sums.add(evaluate_region(model, file, region, with_ssim));
  return sums;
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
