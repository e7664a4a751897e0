// The ZFP side of `vnr bench rd` (include/vnr/rate_distortion.h): its ratio and PSNR on a small volume
// against a direct libzfp round trip and the closed forms of fixed-rate sizes and fixed-accuracy errors.
#include <zfp.h>
#include "test_support.h"
#include "vnr/rate_distortion.h"

using namespace vnr;
using namespace vnr::test;

namespace {

// A float32 volume in data units [lo, hi] = [-3, 5] (normalised values from the Marschner-Lobb field).
Volume test_volume(Int3 dims) {
  Volume v = synth(dims);
  float mn = 1e30f, mx = -1e30f;
  for (float x : v.data) mn = std::min(mn, x), mx = std::max(mx, x);
  for (float& x : v.data) x = (x - mn) / (mx - mn);
  v.lo = -3;
  v.hi = 5;
  v.source_dtype = DType::Float32;
  return v;
}

// PSNR (vnr's: over the value range) of a fixed-accuracy ZFP round trip done here with the raw C API.
double direct_zfp_psnr(const Volume& v, double tolerance) {
  std::vector<float> data(v.data.size()), out(v.data.size());
  for (size_t i = 0; i < data.size(); ++i) data[i] = float(v.lo + double(v.data[i]) * (v.hi - v.lo));
  zfp_field* f = zfp_field_3d(data.data(), zfp_type_float, size_t(v.dims.x), size_t(v.dims.y), size_t(v.dims.z));
  zfp_stream* z = zfp_stream_open(nullptr);
  zfp_stream_set_accuracy(z, tolerance);
  std::vector<unsigned char> buf(zfp_stream_maximum_size(z, f));
  bitstream* b = stream_open(buf.data(), buf.size());
  zfp_stream_set_bit_stream(z, b);
  zfp_compress(z, f);
  zfp_field_set_pointer(f, out.data());
  zfp_stream_rewind(z);
  zfp_decompress(z, f);
  stream_close(b);
  zfp_stream_close(z);
  zfp_field_free(f);
  double se = 0;
  for (size_t i = 0; i < data.size(); ++i) {
    const double d = (double(out[i]) - double(data[i])) / (v.hi - v.lo);
    se += d * d;
  }
  return 10 * std::log10(double(data.size()) / se);
}

}  // namespace

TEST(RateDistortion, ZfpFixedRateSizeIsTheClosedForm) {
  const Volume v = test_volume({16, 16, 8});  // whole 4^3 blocks: exactly rate bits per value
  for (double rate : {2.0, 8.0}) {
    const RdPoint p = zfp_fixed_rate(v, rate);
    EXPECT_EQ(p.bytes, uint64_t(16 * 16 * 8 * rate / 8));
    EXPECT_DOUBLE_EQ(p.ratio, 32.0 / rate);
    EXPECT_GT(p.psnr, 10);
  }
  EXPECT_GT(zfp_fixed_rate(v, 8).psnr, zfp_fixed_rate(v, 2).psnr);
  EXPECT_THROW(zfp_fixed_rate(v, 0), Error);
}

TEST(RateDistortion, ZfpFixedAccuracyMatchesADirectRoundTripAndItsTolerance) {
  const Volume v = test_volume({19, 13, 10});  // partial blocks
  for (double tol : {0.08, 0.008}) {
    const RdPoint p = zfp_fixed_accuracy(v, tol);
    EXPECT_LE(p.max_abs_error, tol);
    EXPECT_NEAR(p.psnr, direct_zfp_psnr(v, tol), 1e-3);  // the bench scores in float, normalised
    EXPECT_NEAR(p.ratio, double(v.dims.count() * 4) / double(p.bytes), 1e-12);
  }
  EXPECT_THROW(zfp_fixed_accuracy(v, -1), Error);
}

// The vnr side end to end on a small volume: a compact model at the ratio, the bound met on it (every
// network tried listed), and PSNR against training time at --time-ratio, each budget its own model.
TEST(RateDistortion, VnrPointsBoundAndTimeAxis) {
  const Volume vol = test_volume(Int3{40, 36, 32});
  RdOptions o;
  o.ratios = {16};
  o.rel_bounds = {1e-2};
  o.zfp_rates = {};
  o.steps = 60;
  o.config = "small";
  o.device = "cpu";
  o.times = {0.3, 1.5};
  o.time_ratio = 16;
  const RdReport r = run_rate_distortion("vol", vol, o);
  const RdPoint *net = nullptr, *bound = nullptr;
  std::vector<const RdPoint*> timed;
  for (const RdPoint& p : r.points) {
    if (p.codec == "vnr") net = &p;
    if (p.codec == "vnr-bound") bound = &p;
    if (p.codec == "vnr-time") timed.push_back(&p);
  }
  ASSERT_TRUE(net && bound);
  EXPECT_NEAR(net->ratio, 16, 16 * 0.05);
  EXPECT_EQ(net->extra["steps"].get<int64_t>(), 60);
  EXPECT_TRUE(bound->extra["bound_holds"].get<bool>());
  ASSERT_EQ(bound->extra["networks_tried"].size(), 1u);
  EXPECT_EQ(bound->extra["networks_tried"][0]["bytes"].get<uint64_t>(), bound->bytes);
  ASSERT_EQ(timed.size(), 2u);
  EXPECT_EQ(timed[0]->parameter, 0.3);
  EXPECT_EQ(timed[1]->parameter, 1.5);
  for (const RdPoint* p : timed) {
    EXPECT_NEAR(p->ratio, 16, 16 * 0.05);
    EXPECT_GE(p->extra["wall_seconds"].get<double>(), p->seconds);  // every phase, training included
    EXPECT_GT(p->extra["steps"].get<int64_t>(), 0);
  }
  // The larger budget trains longer (seconds, not steps: a loaded machine may take fewer steps in it).
  EXPECT_GT(timed[1]->seconds, timed[0]->seconds);
}
