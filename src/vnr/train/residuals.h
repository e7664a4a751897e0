#pragma once
// Error-bound residuals (docs/COMPRESSION.md, "Guaranteed error bound"): the network is the predictor,
// and the quantised difference between the volume and a deterministic evaluation of the network is
// stored beside it, so that every decoded voxel lies within a bound of the original (SZ3's promise).
#include "vnr/training_options.h"
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <vector>
#include "vnr/dtype.h"
#include "vnr/json.h"
#include "vnr/math.h"
#include "vnr/metrics.h"
#include "vnr/nn/network.h"

namespace vnr {

// What the user asked for: a bound in data units (max_error) or as a fraction of the value range
// (max_rel_error); at most one of them positive. Neither: no residuals.

// The bound in normalised units for a volume of range [lo, hi] and source dtype. For integer dtypes a
// bound E >= 0.5 data units is lowered to floor(E) + 0.5, so that the decoded values rounded back to
// the integer type (`vnr decode --dtype source`) still lie within E (and within floor(E)). Fails on a
// non-positive, non-finite or double request.
double normalised_error_bound(const ErrorBoundRequest& request, double lo, double hi, DType source_dtype);
// The bound recorded for residuals whose bound `bound` (normalised) came out of a search rather than a
// request: values decoded within E data units of an integer source round back within E while frac(E) < 1/2
// (or E < 1/2), else within ceil(E), which is then recorded, so that it holds for both decodes.
double bound_after_rounding(double bound, double range, DType source_dtype);

// Safety margin between the guaranteed bound and half the quantisation step, normalised units:
// min(bound / 16, 1e-5). It covers fp32 rounding of the reference on other CPUs (SIMD targets) and of
// the conversion to original units; every decoder applies residuals on the CPU reference, never on the
// GPU's half-precision values (whose ~1e-3 relative difference would eat a 1e-3 bound).
double residual_margin(double bound);

struct EncodedResiduals;

// The quantised residual field: decoded = reference + q * step at voxel i (x fastest) of dims, or, for
// `absolute` residuals, decoded = q * step: the voxels quantised without the network (where that codes
// smaller at a tight bound; the network then only renders and answers point queries).
struct Residuals {
  Int3 dims;
  double bound = 0;  // guaranteed max |decoded - original|, normalised units
  double step = 0;   // 2 (bound - residual_margin(bound))
  bool absolute = false;
  std::vector<int32_t> q;
  // Wavelet residuals (docs/COMPRESSION.md): q are the quantised CDF 9/7 coefficients of the correction
  // (`wavelet_levels` levels, volume/wavelet.h), and `field` the correction at every voxel, inverted once.
  int wavelet_levels = 0;
  // Where a non-zero coefficient of level l (wavelet_coefficient_levels) is rebuilt: sign(q) (|q| +
  // wavelet_offsets[l]) step, the mean of its bin's coefficients (the bins' values are not uniform);
  // empty: at q step (files before the offsets).
  std::vector<double> wavelet_offsets;
  std::shared_ptr<const std::vector<float>> field;
  // Wavelet residuals of a requested bound: the voxels the coefficients leave outside it are corrected by
  // outliers[i] * outlier_step on top (SPERR's outlier coding), folded into `field`; empty: none.
  std::vector<int32_t> outliers;
  double outlier_step = 0;
  // The coded block, when known (after encoding or loading): saving reuses it instead of coding again.
  std::shared_ptr<const EncodedResiduals> encoded;
  int64_t nonzero() const;
  bool wavelet() const { return wavelet_levels > 0; }
  // What decoding adds at voxel i (x fastest), or the value there for absolute residuals.
  float correction(int64_t i) const { return wavelet() ? (*field)[size_t(i)] : float(double(q[size_t(i)]) * step); }
};

// The correction of wavelet residuals at every voxel (r.field) from r.q: the inverse transform, and the
// outliers added (the same float arithmetic when written and read).
void invert_wavelet_residuals(Residuals& r);

// The deterministic reference the residuals are taken against and applied on: the network in fp32
// on the CPU (whatever its inference precision), evaluated in kChunk-sized chunks aligned to the
// volume's voxel index, so that any slab split and any thread count give the same bits.
void reference_slices(const Network& net, Int3 dims, int64_t z0, int64_t z1, float* out);

// The same fp32 evaluation at n voxels given by index (chunks are not aligned here: values may differ
// from reference_slices' in the last bits, well inside residual_margin).
void reference_voxels(const Network& net, Int3 dims, const int64_t* voxel_index, int64_t n, float* out);

// Residuals of `original` (normalised values, dims voxels) against reference_slices, for bound
// (normalised). Checks that the bound holds at every voxel.
Residuals compute_residuals(const Network& net, const float* original, Int3 dims, double bound);

// The bound met without a network: every voxel of `original` quantised with the residuals' step
// (absolute residuals). Coded (3-D Lorenzo over the quantised values, or none, whichever is smaller)
// it is a classical codec's file at this bound (SZ's Lorenzo path).
Residuals quantised_values(const float* original, Int3 dims, double bound);
// Its coded bytes: what sizes the network of a bound given alone (train/config_sizing.h).
uint64_t predictorless_bytes(const float* values, Int3 dims, double bound);
// The residuals a model keeps for `bound`: against the network (compute_residuals) or absolute
// (quantised_values), or wavelet residuals with outliers (bounded_wavelet_residuals), whichever codes
// smallest; coded (`encoded` set, its meta listing the sizes under "reference_bytes" and "candidate_bytes").
Residuals smallest_residuals(const Network& net, const float* original, Int3 dims, double bound);

// The residuals that fill a byte budget (--target-ratio with residuals, docs/COMPRESSION.md): the finest
// bound whose coded block takes at most `budget` bytes (98-100 % of it where the search reaches), against
// the network or absolute and in the coding that ranks first there; coded, with a dead zone (the bound is
// an outcome here, not a request); or the wavelet residuals that fill it, where their squared error is
// smaller. `guaranteed` maps the bound that holds for the decoded values to the
// one recorded (an integer source's rounding, see attach_residuals_for_budget); none: as is. Fails when
// even a bound of half the range does not fit.
Residuals residuals_for_budget(const Network& net, const float* original, Int3 dims, uint64_t budget,
                               const std::function<double(double)>& guaranteed = {});

// The same fill with wavelet residuals (residual_wavelet.cpp): the finest coefficient step that fits,
// against pred or absolute (pred null, or where that codes smaller), field inverted, bound = the largest
// error measured (+ the margin). None when dims are too small for a level or even step 1 does not fit.
std::optional<Residuals> wavelet_residuals_for_budget(const float* original, const float* pred, Int3 dims,
                                                      uint64_t budget);
// Wavelet residuals that hold `bound` (normalised) at every voxel: coefficients quantised at a step
// searched around 1.5 bound, the outliers corrected, against pred or absolute, the smallest block coded;
// none when dims are too small for a level or the bound is under 1e-7 (normalised).
std::optional<Residuals> bounded_wavelet_residuals(const float* original, const float* pred, Int3 dims, double bound);
// The decoded volume's error against `original` over every voxel (pred: the reference, unused for
// absolute residuals), decoded as apply_residuals does.
ErrorStats residual_error_stats(const Residuals& r, const float* original, const float* pred);

// What residuals_for_budget is expected to take on `dims` voxels (0.55 us per voxel: 8.8 s measured on
// bonsai's 16.8 M on 2 cores), and smallest_residuals for a requested bound (1.0 us: 13.6-16.5 s there at
// 1e-2 and 1e-3, the coders of both references running side by side): what a --seconds budget leaves
// them after training.
double residual_fill_seconds(Int3 dims);
double residual_bound_seconds(Int3 dims);

// How the residuals were coded, for reports: residual_bytes, residual_nonzero_fraction,
// residual_bits_per_voxel, codec, predictor, reference (network or none), reference_bytes and
// candidate_bytes. Needs `encoded`.
Json residual_coding_summary(const Residuals& r);

// values (z-slices [z0, z1) of the reference) += q * step; absolute residuals replace them by q * step.
void apply_residuals(const Residuals& r, int64_t z0, int64_t z1, float* values);

// The residual block of a model file: a JSON description and the entropy-coded bytes. The integer
// field is predicted (none, or 3-D Lorenzo from the neighbours already coded, whichever is smaller),
// zig-zag mapped to bytes (values >= 255 escaped to a 4-byte side stream) and compressed with zstd, or
// context coded (residual_context_coder.h); wavelet coefficients are context coded.
struct EncodedResiduals {
  Json meta;
  std::vector<uint8_t> bytes;
};
// `only` (a name of residual_coding_name, e.g. "zstd-values"): that coding alone; `search`: zstd at a
// fast level whose sizes track level 19's in proportion (a budget search's estimates, never saved).
EncodedResiduals encode_residuals(const Residuals& r, const std::string& only = "", bool search = false);
std::string residual_coding_name(const std::string& codec, const std::string& predictor);
// The inverse; any inconsistency between meta, bytes and dims is one clear error naming `what`.
Residuals decode_residuals(const Json& meta, const std::vector<uint8_t>& bytes, Int3 dims, const std::string& what);

}  // namespace vnr
