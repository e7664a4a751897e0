// Wavelet residuals (residuals.h, docs/COMPRESSION.md "Residuals at a ratio"): at a byte budget, the
// correction is coded as dead-zone quantised CDF 9/7 coefficients, which spend the bytes where a smooth
// error has its energy instead of voxel by voxel.
#include <algorithm>
#include <cmath>
#include <optional>
#include "vnr/error.h"
#include "vnr/core/parallel.h"
#include "vnr/train/residual_context_coder.h"
#include "vnr/train/residuals.h"
#include "vnr/volume/wavelet.h"

namespace vnr {

namespace {
// field += the outliers' corrections (the same float arithmetic when written and read).
void fold_outliers(const Residuals& r, std::vector<float>& field) {
  if (r.outliers.empty()) return;
  if (r.outliers.size() != field.size()) fail("wavelet residuals: {} outliers for {} voxels", r.outliers.size(), field.size());
  parallel_for_range(int64_t(field.size()), 1 << 16, [&](int64_t i0, int64_t i1) {
    for (int64_t i = i0; i < i1; ++i)
      if (r.outliers[size_t(i)] != 0)
        field[size_t(i)] = float(double(field[size_t(i)]) + double(r.outliers[size_t(i)]) * r.outlier_step);
  });
}
}  // namespace

void invert_wavelet_residuals(Residuals& r) {
  if (r.q.size() != size_t(r.dims.count())) fail("wavelet residuals of {} values for {} voxels", r.q.size(), r.dims.count());
  const bool offsets = !r.wavelet_offsets.empty();
  if (offsets && r.wavelet_offsets.size() != size_t(r.wavelet_levels) + 1)
    fail("wavelet residuals: {} reconstruction offsets for {} levels", r.wavelet_offsets.size(), r.wavelet_levels);
  const std::vector<uint8_t> level = offsets ? wavelet_coefficient_levels(r.dims, r.wavelet_levels) : std::vector<uint8_t>{};
  auto field = std::make_shared<std::vector<float>>(r.q.size());
  parallel_for_range(int64_t(r.q.size()), 1 << 16, [&](int64_t i0, int64_t i1) {
    for (int64_t i = i0; i < i1; ++i) {
      const double q = r.q[size_t(i)];
      const double rebuilt = offsets && q != 0 ? std::copysign(std::fabs(q) + r.wavelet_offsets[level[size_t(i)]], q) : q;
      (*field)[size_t(i)] = float(rebuilt * r.step);
    }
  });
  wavelet_inverse(*field, r.dims, r.wavelet_levels);
  fold_outliers(r, *field);
  r.field = std::move(field);
}

namespace {

// The dead zone of wavelet coefficients: one of |c| >= (k + zone) step is k steps (JPEG 2000's is 1).
constexpr double kWaveletZone = 0.65;

struct Coefficients {
  std::vector<float> c;
  int levels = 0;
  bool absolute = false;
  std::vector<uint8_t> level;  // wavelet_coefficient_levels
};

Coefficients transform(const float* original, const float* pred, Int3 dims) {
  const int levels = wavelet_levels(dims);
  Coefficients t{std::vector<float>(size_t(dims.count())), levels, pred == nullptr, wavelet_coefficient_levels(dims, levels)};
  parallel_for_range(dims.count(), 1 << 16, [&](int64_t i0, int64_t i1) {
    for (int64_t i = i0; i < i1; ++i) t.c[size_t(i)] = float(double(original[i]) - (pred ? double(pred[i]) : 0.0));
  });
  wavelet_forward(t.c, dims, t.levels);
  return t;
}

Residuals quantise(const Coefficients& t, Int3 dims, double step) {
  Residuals r;
  r.dims = dims;
  r.step = step;
  r.absolute = t.absolute;
  r.wavelet_levels = t.levels;
  r.q.resize(t.c.size());
  const double limit = double(kMaxContextMagnitude);
  parallel_for_range(dims.count(), 1 << 16, [&](int64_t i0, int64_t i1) {
    for (int64_t i = i0; i < i1; ++i) {
      const double c = t.c[size_t(i)], k = std::floor(std::fabs(c) / step + 1 - kWaveletZone);
      r.q[size_t(i)] = int32_t(std::copysign(std::min(k, limit), c));
    }
  });
  // Each level's offset: the mean of |c| / step - |q| over its non-zero coefficients, to 1e-3 (a
  // Laplacian's bins hold more values near their lower end than a uniform one would).
  // Every search step quantises again: the sums go in chunks of fixed size, added in chunk order (the
  // same offsets for any thread count).
  const size_t L = size_t(t.levels) + 1;
  constexpr int64_t kChunk = 1 << 16;
  const int64_t chunks = (dims.count() + kChunk - 1) / kChunk;
  std::vector<double> partial(size_t(chunks) * 2 * L, 0.0);
  parallel_for(chunks, [&](int64_t k) {
    double* sum = partial.data() + size_t(k) * 2 * L;
    for (int64_t i = k * kChunk; i < std::min<int64_t>(dims.count(), (k + 1) * kChunk); ++i)
      if (r.q[size_t(i)] != 0 && std::abs(r.q[size_t(i)]) < kMaxContextMagnitude) {
        sum[t.level[size_t(i)]] += std::fabs(double(t.c[size_t(i)])) / step - std::abs(double(r.q[size_t(i)]));
        sum[L + t.level[size_t(i)]] += 1;
      }
  });
  std::vector<double> sum(L, 0.0), count(L, 0.0);
  for (int64_t k = 0; k < chunks; ++k)
    for (size_t l = 0; l < L; ++l) sum[l] += partial[size_t(k) * 2 * L + l], count[l] += partial[size_t(k) * 2 * L + L + l];
  r.wavelet_offsets.assign(sum.size(), 0.0);
  for (size_t l = 0; l < sum.size(); ++l)
    if (count[l] > 0) r.wavelet_offsets[l] = std::nearbyint(1000 * sum[l] / count[l]) / 1000;
  return r;
}

// The coarsest step whose coded block exceeds `budget` bracketed from above, then bisected in log space
// to the finest step that fits (within 1 % of the budget, or 14 halvings).
Residuals fill(const Coefficients& t, Int3 dims, double budget) {
  auto coded = [&](double step) {
    Residuals r = quantise(t, dims, step);
    r.encoded = std::make_shared<EncodedResiduals>(encode_residuals(r));
    return r;
  };
  double fit = 1.0;
  Residuals best = coded(fit);
  if (double(best.encoded->bytes.size()) > budget) return best;  // the caller rejects it
  double over = fit;
  for (Residuals r = best; double(r.encoded->bytes.size()) <= budget && over > 1e-7;) {
    fit = over, best = std::move(r);
    over /= 4;
    r = coded(over);
  }
  for (int it = 0; it < 14 && double(best.encoded->bytes.size()) < 0.99 * budget; ++it) {
    const double mid = std::sqrt(fit * over);
    Residuals r = coded(mid);
    if (double(r.encoded->bytes.size()) <= budget) fit = mid, best = std::move(r);
    else over = mid;
  }
  return best;
}

// The outliers of wavelet residuals r (field inverted, none yet) for `bound`: where the decoded value
// (reference + field, in float, as decoding adds them) misses the original by more than the bound less
// its margin, the difference in steps of twice that, rounded to nearest; then folded into the field.
void add_outliers(Residuals& r, const float* original, const float* pred, double bound) {
  const double within = bound - residual_margin(bound);
  r.outlier_step = 2 * within;
  std::vector<int32_t> outliers(r.q.size(), 0);
  const std::vector<float>& field = *r.field;
  parallel_for_range(r.dims.count(), 1 << 16, [&](int64_t i0, int64_t i1) {
    for (int64_t i = i0; i < i1; ++i) {
      const float decoded = r.absolute ? field[size_t(i)] : pred[i] + field[size_t(i)];
      const double e = double(original[i]) - double(decoded);
      if (std::fabs(e) > within) outliers[size_t(i)] = int32_t(std::nearbyint(e / r.outlier_step));
    }
  });
  if (std::all_of(outliers.begin(), outliers.end(), [](int32_t o) { return o == 0; })) return;
  r.outliers = std::move(outliers);
  auto folded = std::make_shared<std::vector<float>>(field);
  fold_outliers(r, *folded);
  r.field = std::move(folded);
}

}  // namespace

std::optional<Residuals> bounded_wavelet_residuals(const float* original, const float* pred, Int3 dims, double bound) {
  if (!(bound > 0) || !std::isfinite(bound)) fail("the error bound must be positive, got {}", bound);
  // Below 1e-7 of the range (fp32's own precision) the outliers' steps could leave the coder's range.
  if (wavelet_levels(dims) == 0 || bound < 1e-7) return std::nullopt;
  auto candidate = [&](const Coefficients& t, double step) {
    Residuals r = quantise(t, dims, step);
    r.bound = bound;
    invert_wavelet_residuals(r);
    add_outliers(r, original, pred, bound);
    r.encoded = std::make_shared<EncodedResiduals>(encode_residuals(r));
    return r;
  };
  auto bytes = [](const Residuals& r) { return r.encoded->bytes.size(); };
  // The reference at the middle step, then the step in factors of 1.5 downhill (the total of coefficients
  // and outliers falls, then rises, as the step grows).
  std::optional<Coefficients> t = transform(original, pred, dims);
  Residuals best = candidate(*t, 1.5 * bound);
  Json reference_bytes = {{"network", bytes(best)}};
  {
    Coefficients values = transform(original, nullptr, dims);
    Residuals alone = candidate(values, 1.5 * bound);
    reference_bytes["none"] = bytes(alone);
    if (bytes(alone) < bytes(best)) best = std::move(alone), t = std::move(values);
  }
  const double start = best.step;
  for (double factor : {1.5, 1 / 1.5}) {
    if (factor < 1 && best.step != start) break;  // it fell upwards: the smaller steps lie behind
    for (double step = best.step * factor; step > 0.25 * bound && step < 16 * bound; step *= factor) {
      Residuals r = candidate(*t, step);
      if (bytes(r) >= bytes(best)) break;
      best = std::move(r);
    }
  }
  if (residual_error_stats(best, original, pred).max_abs_error > bound) return std::nullopt;  // fp32 rounding beyond the margin
  auto enc = std::make_shared<EncodedResiduals>(*best.encoded);
  enc->meta["reference_bytes"] = reference_bytes;  // at 1.5 bound
  best.encoded = std::move(enc);
  return best;
}

ErrorStats residual_error_stats(const Residuals& r, const float* original, const float* pred) {
  std::vector<float> decoded(size_t(r.dims.count()), 0.0f);
  if (!r.absolute) std::copy_n(pred, decoded.size(), decoded.begin());
  apply_residuals(r, 0, r.dims.z, decoded.data());  // decoding's own arithmetic
  return error_stats(original, decoded.data(), r.dims);
}

std::optional<Residuals> wavelet_residuals_for_budget(const float* original, const float* pred, Int3 dims,
                                                      uint64_t budget) {
  if (wavelet_levels(dims) == 0) return std::nullopt;
  const double goal = double(budget);
  Residuals best = fill(transform(original, pred, dims), dims, goal);
  // The voxels' own coefficients, where they code smaller at that step (the network predicts little there).
  const Coefficients values = transform(original, nullptr, dims);
  Residuals alone = quantise(values, dims, best.step);
  alone.encoded = std::make_shared<EncodedResiduals>(encode_residuals(alone));
  if (alone.encoded->bytes.size() < best.encoded->bytes.size()) best = fill(values, dims, goal);
  if (double(best.encoded->bytes.size()) > goal) return std::nullopt;
  invert_wavelet_residuals(best);
  const double worst = residual_error_stats(best, original, pred).max_abs_error;
  best.bound = worst + residual_margin(worst);
  return best;
}

}  // namespace vnr
