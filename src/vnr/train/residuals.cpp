#include "vnr/train/residuals.h"
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <optional>
#include "vnr/error.h"
#include "vnr/core/parallel.h"
#include "vnr/train/residual_context_coder.h"
#include "vnr/volume/volume.h"

namespace vnr {

double normalised_error_bound(const ErrorBoundRequest& req, double lo, double hi, DType source_dtype) {
  if (req.max_error > 0 && req.max_rel_error > 0) fail("give either --max-error or --max-rel-error, not both");
  if (!(req.max_error >= 0) || !(req.max_rel_error >= 0) || !std::isfinite(req.max_error) ||
      !std::isfinite(req.max_rel_error) || !req.active())
    fail("the error bound must be a positive number, got {}", req.max_error > 0 ? req.max_error : req.max_rel_error);
  if (req.max_rel_error >= 1) fail("--max-rel-error is a fraction of the value range and must be below 1, got {}", req.max_rel_error);
  const double range = hi - lo;
  if (!(range > 0)) fail("the volume's value range [{}, {}] is empty: an error bound needs hi > lo", lo, hi);
  double e = req.max_error > 0 ? req.max_error : req.max_rel_error * range;  // data units
  if (dtype_is_integer(source_dtype) && e >= 0.5) e = std::min(e, std::floor(e) + 0.5);
  return e / range;
}

double bound_after_rounding(double bound, double range, DType source_dtype) {
  const double e = bound * range;
  if (!dtype_is_integer(source_dtype) || e < 0.5 || e - std::floor(e) < 0.5) return bound;
  return std::ceil(e) / range;
}

double residual_margin(double bound) { return std::min(bound / 16, 1e-5); }

int64_t Residuals::nonzero() const {
  return int64_t(q.size()) - std::count(q.begin(), q.end(), 0);
}

namespace {
// net itself when it infers in fp32, else an fp32 copy held in `copy`.
const Network& fp32_network(const Network& net, std::optional<Network>& copy) {
  if (net.inference_precision() == Precision::FP32) return net;
  copy.emplace(net);
  copy->set_inference_precision(Precision::FP32);
  return *copy;
}
}  // namespace

void reference_voxels(const Network& net, Int3 dims, const int64_t* voxel_index, int64_t n, float* out) {
  std::optional<Network> copy;
  fp32_network(net, copy).infer_fn(
      n, [&](int64_t i, float* x, float* y, float* z) { voxel_centre(dims, voxel_index[i], x, y, z); }, out);
}

void reference_slices(const Network& net, Int3 dims, int64_t z0, int64_t z1, float* out) {
  std::optional<Network> copy;
  const Network* ref = &fp32_network(net, copy);
  // Widen [first, last) to chunk boundaries of the whole volume: every voxel then sits in the same chunk
  // (same kernels, same padding) whatever slab it was asked in.
  const int64_t total = dims.count(), first = dims.x * dims.y * z0, last = dims.x * dims.y * z1;
  const int64_t a = first / kChunk * kChunk, b = std::min(total, (last + kChunk - 1) / kChunk * kChunk);
  std::vector<float> tmp;
  float* dst = out;
  if (a != first || b != last) {
    tmp.resize(size_t(b - a));
    dst = tmp.data();
  }
  ref->infer_fn(
      b - a, [&](int64_t i, float* x, float* y, float* z) { voxel_centre(dims, a + i, x, y, z); }, dst);
  if (dst != out) std::copy(tmp.begin() + (first - a), tmp.begin() + (last - a), out);
}

namespace {
float correction(const Residuals& r, int32_t q) { return float(double(q) * r.step); }

// Residuals of `original` against `pred` (null: against 0, absolute) at the step of `bound`; the number
// of voxels where they cannot hold the bound is returned in *violations. `zone` >= 0.5: a difference of
// d steps rounds up from |d| = k + zone, not k + 1/2 (a dead zone: fewer, smaller indices for a larger
// error, zone steps; 0.5 rounds to nearest); the bound kept is then zone * step + the margin.
Residuals quantise(const float* original, const float* pred, Int3 dims, double bound, int64_t* violations,
                   double zone = 0.5) {
  if (!(bound > 0) || !std::isfinite(bound)) fail("the error bound must be positive, got {}", bound);
  Residuals r;
  r.dims = dims;
  r.step = 2 * (bound - residual_margin(bound));
  r.bound = zone == 0.5 ? bound : zone * r.step + residual_margin(bound);
  r.absolute = pred == nullptr;
  r.q.resize(size_t(dims.count()));
  const double limit = double(1 << 27);  // so that Lorenzo sums of seven stay far inside int32
  std::atomic<int64_t> bad_total{0};
  parallel_for_range(dims.count(), 1 << 16, [&](int64_t i0, int64_t i1) {
    int64_t bad = 0;
    for (int64_t i = i0; i < i1; ++i) {
      const float p = pred ? pred[size_t(i)] : 0.0f;
      const double steps = (double(original[i]) - double(p)) / r.step;
      const double d = zone == 0.5 ? std::nearbyint(steps) : std::copysign(std::floor(std::fabs(steps) + 1 - zone), steps);
      if (!(std::fabs(d) < limit)) {
        ++bad;
        continue;
      }
      r.q[size_t(i)] = int32_t(d);
      const float decoded = p + correction(r, r.q[size_t(i)]);  // p = 0 adds nothing
      if (!(std::fabs(double(decoded) - double(original[i])) <= r.bound)) ++bad;
    }
    bad_total += bad;
  });
  *violations = bad_total.load();
  return r;
}
}  // namespace

Residuals quantised_values(const float* original, Int3 dims, double bound) {
  int64_t violations = 0;
  Residuals r = quantise(original, nullptr, dims, bound, &violations);
  if (violations > 0)
    fail("cannot meet the error bound {:.3g} (normalised) at {} voxels without a network", bound, violations);
  return r;
}

uint64_t predictorless_bytes(const float* values, Int3 dims, double bound) {
  return encode_residuals(quantised_values(values, dims, bound)).bytes.size();
}

namespace {
// Both coded; the smaller kept, its description listing both sizes.
Residuals smaller_coded(Residuals net_res, Residuals abs_res) {
  auto net_enc = std::make_shared<EncodedResiduals>(encode_residuals(net_res));
  auto abs_enc = std::make_shared<EncodedResiduals>(encode_residuals(abs_res));
  const Json sizes = {{"network", net_enc->bytes.size()}, {"none", abs_enc->bytes.size()}};
  net_enc->meta["reference_bytes"] = sizes;
  abs_enc->meta["reference_bytes"] = sizes;
  net_res.encoded = std::move(net_enc);
  abs_res.encoded = std::move(abs_enc);
  return abs_res.encoded->bytes.size() < net_res.encoded->bytes.size() ? std::move(abs_res) : std::move(net_res);
}

std::vector<float> network_prediction(const Network& net, Int3 dims) {
  std::vector<float> pred(static_cast<size_t>(dims.count()));
  reference_slices(net, dims, 0, dims.z, pred.data());
  return pred;
}

// pred null: absolute residuals.
Residuals against_prediction(const float* original, const float* pred, Int3 dims, double bound, double zone = 0.5) {
  int64_t violations = 0;
  Residuals r = quantise(original, pred, dims, bound, &violations, zone);
  if (violations > 0)
    fail("cannot meet the error bound {:.3g} (normalised) at {} voxels: the bound is too small for fp32 values, or "
         "the network's output is not finite", bound, violations);
  return r;
}
}  // namespace

namespace {
// Whether wavelet residuals may code a bound smaller than voxel residuals, judged on the central box of
// half the dims (an eighth of the voxels) of a large volume: their search costs several passes over the
// volume, and on most volumes and bounds the voxel residuals stay smaller (docs/COMPRESSION.md).
bool wavelet_may_win(const float* original, const float* pred, Int3 dims, double bound) {
  if (dims.count() < (int64_t(1) << 21)) return true;  // small: the whole search is cheap
  const Int3 sub{std::max<int64_t>(dims.x / 2, 1), std::max<int64_t>(dims.y / 2, 1), std::max<int64_t>(dims.z / 2, 1)};
  const Int3 at{(dims.x - sub.x) / 2, (dims.y - sub.y) / 2, (dims.z - sub.z) / 2};
  std::vector<float> o(size_t(sub.count())), p(size_t(sub.count()));
  parallel_for(sub.z, [&](int64_t z) {
    for (int64_t y = 0; y < sub.y; ++y) {
      const int64_t from = at.x + dims.x * (at.y + y + dims.y * (at.z + z)), to = sub.x * (y + sub.y * z);
      std::copy_n(original + from, sub.x, o.begin() + to);
      std::copy_n(pred + from, sub.x, p.begin() + to);
    }
  });
  const Residuals voxels = smaller_coded(against_prediction(o.data(), p.data(), sub, bound), quantised_values(o.data(), sub, bound));
  const std::optional<Residuals> wavelet = bounded_wavelet_residuals(o.data(), p.data(), sub, bound);
  return wavelet && wavelet->encoded->bytes.size() < voxels.encoded->bytes.size();
}
}  // namespace

Residuals smallest_residuals(const Network& net, const float* original, Int3 dims, double bound) {
  if (!(bound > 0) || !std::isfinite(bound)) fail("the error bound must be positive, got {}", bound);
  const std::vector<float> pred = network_prediction(net, dims);
  Residuals voxels = smaller_coded(against_prediction(original, pred.data(), dims, bound), quantised_values(original, dims, bound));
  std::optional<Residuals> wavelet;
  if (wavelet_may_win(original, pred.data(), dims, bound))
    wavelet = bounded_wavelet_residuals(original, pred.data(), dims, bound);
  const size_t voxel_bytes = voxels.encoded->bytes.size();
  if (!wavelet || wavelet->encoded->bytes.size() >= voxel_bytes) return voxels;
  auto enc = std::make_shared<EncodedResiduals>(*wavelet->encoded);
  enc->meta["candidate_bytes"]["voxels"] = voxel_bytes;
  wavelet->encoded = std::move(enc);
  return std::move(*wavelet);
}

namespace {
// The finest bound whose size(bound) is at most `goal`, as the search finds it: sizes fall with
// the bound about as a power of it, so bracket, then regula falsi in log-log with the Illinois rule until
// within 1 % under the goal. Bounds from 1e-6 (finer is pointless) to 0.5 (half the range).
double finest_bound_within(const std::function<double(double)>& size, double goal) {
  double fit = 0.5, fit_bytes = size(fit);
  if (fit_bytes > goal) return fit;
  double over = 0.02, over_bytes = size(over);
  while (over_bytes <= goal && over > 1e-6) {
    fit = over, fit_bytes = over_bytes;
    over /= 8, over_bytes = size(over);
  }
  if (over_bytes <= goal) return over;
  double f_over = std::log(over_bytes / goal), f_fit = std::log(fit_bytes / goal);  // > 0, <= 0
  for (int side = 0, it = 0; fit_bytes < 0.99 * goal && it < 12; ++it) {
    const double a = std::log(over), b = std::log(fit);
    double t = b - f_fit * (b - a) / (f_fit - f_over);
    if (!(t > a && t < b)) t = 0.5 * (a + b);
    const double e = std::exp(t), bytes = size(e), f = std::log(bytes / goal);
    if (bytes <= goal) {
      fit = e, fit_bytes = bytes, f_fit = f;
      if (side == +1) f_over /= 2;
      side = +1;
    } else {
      over = e, f_over = f;
      if (side == -1) f_fit /= 2;
      side = -1;
    }
  }
  return fit;
}
}  // namespace

// The dead zone of residuals that fill a budget (quantise): there the bound is an outcome, not a request,
// and a wider zero bin buys more PSNR per byte than rounding to nearest (docs/COMPRESSION.md).
constexpr double kFillZone = 0.65;

namespace {
// The voxel-coded residuals or the wavelet ones, whichever decodes with the smaller squared error; both
// errors are kept in the description ("candidate_squared_error").
Residuals smaller_error(Residuals voxels, std::optional<Residuals> wavelet, const float* original, const float* pred,
                        const std::function<double(double)>& guaranteed) {
  if (!wavelet) return voxels;
  const double n = double(voxels.dims.count());  // squared errors summed over the voxels
  const double e_voxels = residual_error_stats(voxels, original, pred).mse * n;
  const double e_wavelet = residual_error_stats(*wavelet, original, pred).mse * n;
  Residuals& kept = e_wavelet < e_voxels ? *wavelet : voxels;
  if (&kept == &*wavelet && guaranteed) kept.bound = guaranteed(kept.bound);
  auto enc = std::make_shared<EncodedResiduals>(*kept.encoded);
  enc->meta["bound"] = kept.bound;
  enc->meta["candidate_squared_error"] = {{"voxels", e_voxels}, {"wavelet", e_wavelet}};
  if (kept.wavelet()) enc->meta["reference_bytes"] = {{kept.absolute ? "none" : "network", enc->bytes.size()}};
  kept.encoded = std::move(enc);
  return std::move(kept);
}
}  // namespace

Residuals residuals_for_budget(const Network& net, const float* original, Int3 dims, uint64_t budget,
                               const std::function<double(double)>& guaranteed) {
  const std::vector<float> pred = network_prediction(net, dims);
  auto quantised = [&](double bound, bool absolute) {
    Residuals r = against_prediction(original, absolute ? nullptr : pred.data(), dims, bound, kFillZone);
    if (guaranteed) r.bound = guaranteed(r.bound);  // what the coded description records
    return r;
  };
  auto size_of = [](const Residuals& r, const std::string& only, bool search) {
    return double(encode_residuals(r, only, search).bytes.size());
  };
  const double target = double(budget);
  // The bound where the context coder against the network (one fast pass) fills the budget; there every
  // coding of both references is ranked, zstd at its fast level (taken at 0.9: level 19 codes ~10 %
  // smaller), and only the first is coded for the file (zstd level 19 takes seconds on a large volume).
  // A zstd winner is searched again on its fast level, scaled to level 19 by their ratio at the last
  // bound, until the block fills 98-100 % of the budget (three rounds at most).
  double bound = finest_bound_within([&](double b) { return size_of(quantised(b, false), "context-none", false); }, target);
  Json ranked = Json::object();
  for (bool absolute : {false, true}) {
    const EncodedResiduals fast = encode_residuals(quantised(bound, absolute), "", true);
    for (const auto& [name, bytes] : fast.meta["candidate_bytes"].items())
      ranked[name] = bytes.get<double>() * (name.rfind("zstd", 0) == 0 ? 0.9 : 1.0);
  }
  std::string winner;
  for (const auto& [name, bytes] : ranked.items())
    if (winner.empty() || bytes.get<double>() < ranked[winner].get<double>()) winner = name;
  const bool absolute = winner.find("-values") != std::string::npos;
  std::optional<Residuals> best;  // the largest block that fits
  for (int round = 0;; ++round) {
    Residuals r = quantised(bound, absolute);
    auto enc = std::make_shared<EncodedResiduals>(encode_residuals(r, winner));
    const double bytes = double(enc->bytes.size());
    enc->meta["reference_bytes"] = {{absolute ? "none" : "network", enc->bytes.size()}};
    r.encoded = std::move(enc);
    const bool fits = bytes <= target;
    if (fits && (!best || bytes > double(best->encoded->bytes.size()))) best = r;
    if ((fits && bytes >= 0.98 * target) || winner.rfind("context", 0) == 0 || round == 2) break;
    const double scale = bytes / size_of(r, winner, true);
    const double next = finest_bound_within([&](double b) { return scale * size_of(quantised(b, absolute), winner, true); },
                                            target);
    if (next == bound) break;
    bound = next;
  }
  if (!best) {
    best = smaller_coded(quantised(0.5, false), quantised(0.5, true));
    if (double(best->encoded->bytes.size()) > target)
      fail("residuals: even a bound of half the range takes {} bytes, over the {} left", best->encoded->bytes.size(),
           budget);
  }
  return smaller_error(std::move(*best), wavelet_residuals_for_budget(original, pred.data(), dims, budget), original,
                       pred.data(), guaranteed);
}

double residual_fill_seconds(Int3 dims) { return 0.55e-6 * double(dims.count()); }
double residual_bound_seconds(Int3 dims) { return 1.0e-6 * double(dims.count()); }

Json residual_coding_summary(const Residuals& r) {
  if (!r.encoded) fail("the residuals were not coded");
  const EncodedResiduals& enc = *r.encoded;
  const double voxels = double(r.dims.count()), bytes = double(enc.bytes.size());
  return {{"residual_bytes", enc.bytes.size()},
          {"residual_nonzero_fraction", double(r.nonzero()) / voxels},
          {"residual_bits_per_voxel", 8.0 * bytes / voxels},
          {"codec", enc.meta["codec"]},
          {"transform", r.wavelet() ? "wavelet-cdf97" : "none"},
          {"predictor", enc.meta["predictor"]},
          {"reference", r.absolute ? "none" : "network"},
          {"reference_bytes", enc.meta.value("reference_bytes", Json())},
          {"candidate_bytes", enc.meta.value("candidate_bytes", Json())}};
}

Residuals compute_residuals(const Network& net, const float* original, Int3 dims, double bound) {
  if (!(bound > 0) || !std::isfinite(bound)) fail("the error bound must be positive, got {}", bound);
  const std::vector<float> pred = network_prediction(net, dims);
  return against_prediction(original, pred.data(), dims, bound);
}

void apply_residuals(const Residuals& r, int64_t z0, int64_t z1, float* values) {
  const int64_t plane = r.dims.x * r.dims.y, first = plane * z0, n = plane * (z1 - z0);
  if (z0 < 0 || z1 > r.dims.z || z0 > z1) fail("residual slab [{}, {}) is outside 0..{}", z0, z1, r.dims.z);
  const int32_t* q = r.q.data() + first;
  parallel_for_range(n, 1 << 16, [&](int64_t i0, int64_t i1) {
    if (r.wavelet()) {
      const float* c = r.field->data() + first;
      for (int64_t i = i0; i < i1; ++i) values[i] = r.absolute ? c[i] : values[i] + c[i];
    } else if (r.absolute)
      for (int64_t i = i0; i < i1; ++i) values[i] = correction(r, q[i]);
    else
      for (int64_t i = i0; i < i1; ++i)
        if (q[i] != 0) values[i] += correction(r, q[i]);
  });
}

}  // namespace vnr
