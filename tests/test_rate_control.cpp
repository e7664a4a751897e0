// Compact storage through the library API: --target-ratio's exact file size, --target-psnr, and the
// quantized model that the file holds (train/rate_control.h).
#include <gtest/gtest.h>
#include <cmath>
#include <cstring>
#include <fmt/format.h>
#include "vnr/fileio.h"
#include "vnr/core/half.h"
#include "vnr/core/parallel.h"
#include "vnr/nn/mlp_layout.h"
#include "vnr/train/config_sizing.h"
#include "vnr/trainer.h"
#include "vnr/train/rate_control.h"
#include "vnr/train/rate_term.h"
#include "vnr/train/session.h"
#include "test_support.h"

using namespace vnr;
using namespace vnr::test;

namespace {

double smooth_field(double x, double y, double z) {
  return 0.5 + 0.3 * std::sin(3.0 * x) * std::cos(2.0 * y) + 0.2 * z * z;
}

// A smooth field stored as `dtype` (uint8, int16 or float32) at d/v.raw.
std::string write_volume(const std::string& d, Int3 dims, const std::string& dtype) {
  std::string bytes;
  for (int64_t z = 0; z < dims.z; ++z)
    for (int64_t y = 0; y < dims.y; ++y)
      for (int64_t x = 0; x < dims.x; ++x) {
        const double v = smooth_field(double(x) / dims.x, double(y) / dims.y, double(z) / dims.z);
        if (dtype == "uint8") {
          bytes.push_back(char(uint8_t(std::lround(v * 255))));
        } else if (dtype == "int16") {
          const int16_t s = int16_t(std::lround(v * 20000 - 5000));
          bytes.append(reinterpret_cast<const char*>(&s), 2);
        } else {
          const float f = float(v);
          bytes.append(reinterpret_cast<const char*>(&f), 4);
        }
      }
  const std::string path = d + "/v_" + dtype + ".raw";
  write_bytes(path, bytes);
  return path;
}

TrainingSetup setup_for(const std::string& d, const std::string& volume, Int3 dims, const std::string& dtype) {
  // The trained networks (and so the PSNR thresholds below) depend on the thread count: fix it, so that
  // a machine with more cores runs the same numbers.
  set_num_threads(2);
  TrainingSetup s;
  s.volume = volume;
  s.raw.dims = dims;
  s.raw.dtype = dtype;
  s.config = "small";
  s.batch = 4096;
  s.seed = 5;
  s.device = "cpu";
  s.session.output = d + "/m.vnr";
  return s;
}

}  // namespace

// The file lands within 5 % of volume_bytes / R (vnr aims just under it), for several sizes and dtypes,
// and the model it holds is the one the session evaluated: quantized values, loaded exactly.
TEST(RateControl, TargetRatioGivesTheFileSize) {
  const std::string d = temp_dir("rate_ratio");
  struct Case {
    Int3 dims;
    std::string dtype;
    double ratio;
  };
  for (const Case& c : {Case{{40, 40, 40}, "uint8", 8}, Case{{48, 40, 32}, "float32", 32},
                        Case{{56, 24, 40}, "int16", 12}}) {
    SCOPED_TRACE(c.dtype);
    TrainingSetup s = setup_for(d, write_volume(d, c.dims, c.dtype), c.dims, c.dtype);
    s.target_ratio = c.ratio;
    auto session = open_training_session(s);
    const CompactOptions& o = session->options().compact;
    const uint64_t volume_bytes = uint64_t(c.dims.count()) * dtype_size(parse_dtype(c.dtype));
    ASSERT_EQ(o.target_bytes, uint64_t(double(volume_bytes) / c.ratio));
    const Json summary = train_compact(*session, 40, 0, o);
    EXPECT_EQ(summary["qat_steps"].get<int64_t>(), 6);  // the last 15 % of 40 steps
    const TrainingResult r = session->finish({.ssim = false});
    const double size = double(file_size(s.session.output));
    EXPECT_LE(size, double(o.target_bytes));
    EXPECT_GE(size, 0.95 * double(o.target_bytes));
    EXPECT_EQ(uint64_t(size), r.model_bytes);
    Model m = load_model(s.session.output);
    EXPECT_FALSE(m.param_segments.empty());
    EXPECT_EQ(m.net->params_half(), session->network().params_half());
  }
}

// --target-psnr: the coarsest quantization that keeps the held-back PSNR, far smaller than fp16,
// and the final full evaluation near the estimate.
// Reaches the target with the coarsest steps that do, on networks trained with 1 to 4 threads (each a
// slightly different network: the search must not depend on one network's luck; it failed on 1 and 4
// before the plan's estimates were antithetic and the search after the quantization-aware steps
// started from their scale).
TEST(RateControl, TargetPsnrKeepsTheQualityAtTheSmallestSize) {
  const std::string d = temp_dir("rate_psnr");
  const Int3 dims{32, 32, 32};
  TrainingSetup s = setup_for(d, write_volume(d, dims, "float32"), dims, "float32");
  s.target_psnr = 32;
  for (int threads = 1; threads <= 4; ++threads) {
    SCOPED_TRACE(fmt::format("{} threads", threads));
    set_num_threads(threads);
    auto session = open_training_session(s);
    const Json summary = train_compact(*session, 300, 0, session->options().compact);
    ASSERT_GE(summary["heldback_psnr_unquantized"].get<double>(), 34.0) << summary.dump();
    EXPECT_GE(summary["heldback_psnr"].get<double>(), 32.0) << summary.dump();
    EXPECT_LT(summary["heldback_psnr"].get<double>(), 33.0) << summary.dump();  // the coarsest steps that still reach it
    const TrainingResult r = session->finish({.ssim = false});
    EXPECT_NEAR(r.psnr, summary["heldback_psnr"].get<double>(), 0.5);  // random voxels estimate the full PSNR
    EXPECT_LT(double(r.model_bytes), 0.5 * double(session->network().n_params() * 2));
  }
  set_num_threads(2);
}

TEST(RateControl, BadTargetsAreOneLineErrors) {
  TrainingSetup s;
  s.target_ratio = -2;
  EXPECT_NE(one_line_error_of([&] { check_training_setup(s); }).find("--target-ratio must be positive"),
            std::string::npos);
  s.target_ratio = 0;
  s.target_psnr = std::nan("");
  EXPECT_NE(one_line_error_of([&] { check_training_setup(s); }).find("--target-psnr must be positive"),
            std::string::npos);
}

// A budget below what the header and macro-cells alone take is refused with the smallest size.
TEST(RateControl, ImpossibleBudgetIsRefused) {
  const std::string d = temp_dir("rate_small");
  const Int3 dims{24, 24, 24};
  TrainingSetup s = setup_for(d, write_volume(d, dims, "uint8"), dims, "uint8");
  s.target_ratio = 100;  // 138 bytes
  auto session = open_training_session(s);
  const std::string msg = one_line_error_of([&] { train_compact(*session, 10, 0, session->options().compact); });
  EXPECT_NE(msg.find("below the smallest file this model can make"), std::string::npos) << msg;
}

// A front end that only run()s a compact session (the Python module, a viewer) still gets a file that
// meets the target: finish() quantizes after training.
TEST(RateControl, FinishQuantizesARunOnlySession) {
  const std::string d = temp_dir("rate_finish");
  const Int3 dims{40, 32, 24};
  TrainingSetup s = setup_for(d, write_volume(d, dims, "float32"), dims, "float32");
  s.target_ratio = 16;
  auto session = open_training_session(s);
  session->run(20);
  const TrainingResult r = session->finish({.ssim = false});
  const uint64_t target = session->options().compact.target_bytes;
  EXPECT_LE(r.model_bytes, target);
  EXPECT_GE(double(r.model_bytes), 0.95 * double(target));
  ASSERT_TRUE(r.report.contains("compact"));
  EXPECT_EQ(r.report["compact"]["qat_steps"].get<int64_t>(), 0);
  EXPECT_EQ(load_model(s.session.output).net->params_half(), session->network().params_half());
}

// The plan's sensitivities predict what quantizing one segment costs: a_i = n_i / shape_i^2 is the
// probe MSE's growth per squared step. Measured against quantizing each segment alone at a step of
// a fraction of its values' spread, within a factor of 10 either way (2.5 for segments of 1,024
// parameters or more: a small one has few directions, so one quantization pattern is itself a noisy
// sample), for every segment, on networks trained with 1 to 4 threads. The output layer included:
// there one noise draw's first-order term could hide the curvature and make the prediction 10^4 times
// too small.
TEST(RateControl, PlanPredictsTheCostOfQuantizingEachSegment) {
  const std::string d = temp_dir("rate_plan");
  const Int3 dims{32, 32, 32};
  TrainingSetup s = setup_for(d, write_volume(d, dims, "float32"), dims, "float32");
  for (int threads = 1; threads <= 4; ++threads) {
    SCOPED_TRACE(fmt::format("{} threads", threads));
    set_num_threads(threads);
    auto session = open_training_session(s);
    session->run(300);
    Network& net = session->network();
    const ProbeSet probe = draw_voxel_probe(*session->data()->vol, 1 << 15, 11);
    const QuantPlan plan = plan_quantization(net, probe);
    const std::vector<float> master(net.params().begin(), net.params().end());
    std::vector<ParamSegment> raw = plan.segments;  // steps 0: the fp16 values
    apply_quantization(net, master, raw);
    const double base = probe.mse(net);
    uint64_t off = 0;
    for (size_t i = 0; i < plan.segments.size(); ++i) {
      const uint64_t n = plan.segments[i].count;
      double sq = 0;
      uint64_t live = 0;
      for (uint64_t k = off; k < off + n; ++k) sq += double(master[k]) * master[k], live += master[k] != 0;
      const double step = 0.3 * std::sqrt(sq / double(std::max<uint64_t>(live, 1)));
      std::vector<ParamSegment> one = raw;
      one[i].step = float(step);
      apply_quantization(net, master, one);
      const double measured = probe.mse(net) - base;
      const double predicted = double(n) / (plan.shape[i] * plan.shape[i]) * step * step;
      const double band = n >= 1024 ? 2.5 : 10;
      EXPECT_GT(measured, predicted / band) << "segment " << i << " of " << n << " parameters";
      EXPECT_LT(measured, predicted * band) << "segment " << i << " of " << n << " parameters";
      off += n;
    }
    // Finer than 10-bit indices allow, a segment keeps its fp16 values: the finest scale is lossless.
    const std::vector<ParamSegment> finest = plan.at(1e-12);
    for (const ParamSegment& seg : finest) EXPECT_EQ(seg.step, 0.0f);
    apply_quantization(net, master, finest);
    EXPECT_EQ(probe.mse(net), base);
  }
  set_num_threads(2);
}

namespace {

PsnrSearch search_on(const std::string& d, double target_psnr) {
  const Int3 dims{32, 32, 32};
  TrainingSetup s = setup_for(d, write_volume(d, dims, "float32"), dims, "float32");
  s.target_psnr = target_psnr;
  return search_size_for_psnr(s, 150, 0, [](const TrainingSetup& c) { return open_training_session(c); });
}

double ratio_of(const Json& tried, bool reached_wanted, bool smallest) {
  double best = 0;
  for (const Json& t : tried)
    if (t["reached"].get<bool>() == reached_wanted) {
      const double r = t["ratio"].get<double>();
      if (best == 0 || (smallest ? r > best : r < best)) best = r;
    }
  return best;
}

}  // namespace

// --target-psnr alone: bisection over the sizes returns the smallest that reaches the target. The next
// smaller size was trained and fell short, no smaller size reached it, and the full evaluation of the
// chosen (quantized) model agrees with its held-back estimate.
TEST(RateControl, TargetPsnrSearchFindsTheSmallestModelThatReachesIt) {
  const std::string d = temp_dir("rate_search");
  PsnrSearch found = search_on(d, 30);
  ASSERT_TRUE(found.reached) << found.tried.dump();
  ASSERT_TRUE(found.session);
  EXPECT_LE(found.tried.size(), 4u);  // 9 sizes: at most ceil(log2 9) trainings
  const uint64_t volume_bytes = 32 * 32 * 32 * 4;
  const double chosen = double(volume_bytes) / double(found.session->options().compact.target_bytes);
  EXPECT_EQ(chosen, ratio_of(found.tried, true, true)) << found.tried.dump();  // the smallest that reached
  if (chosen < 1024) EXPECT_EQ(ratio_of(found.tried, false, false), chosen * 2) << found.tried.dump();
  const TrainingResult r = found.session->finish({.ssim = false});
  EXPECT_GE(r.psnr, 29.5);
  EXPECT_LE(r.model_bytes, found.session->options().compact.target_bytes);
}

// A target no size reaches: the largest model, marked as short of it, after log2(9) trainings.
TEST(RateControl, TargetPsnrSearchOutOfReachKeepsTheLargestModel) {
  const std::string d = temp_dir("rate_search_far");
  PsnrSearch found = search_on(d, 80);
  EXPECT_FALSE(found.reached);
  ASSERT_TRUE(found.session);
  EXPECT_EQ(found.session->options().compact.target_bytes, uint64_t(32 * 32 * 32 * 4 / 4));
  EXPECT_EQ(found.tried.size(), 4u);
  EXPECT_EQ(ratio_of(found.tried, true, true), 0);
}

// The rate term: bits of a Laplace bin around theta against an independent integration of the
// density, its gradient against central finite differences, and the masses of all bins summing to 1.
// nn/quantization_hd.h's stored value, shared by the CPU's quantization-aware steps and the GPU's kernel:
// the nearest multiple (ties to even), at most kMaxQuantIndex steps out, rounded to fp16, NaN/inf to 0.
TEST(RateTerm, QuantizedValueIsTheNearestStoredMultiple) {
  const auto fp16 = [](float v) { return half_to_float(float_to_half(v)); };
  EXPECT_EQ(quantized_value(0.26f, 0.1f), fp16(3 * 0.1f));
  EXPECT_EQ(quantized_value(0.75f, 0.5f), 1.0f);  // 1.5 steps: to the even 2
  EXPECT_EQ(quantized_value(1.25f, 0.5f), 1.0f);  // 2.5 steps: to the even 2
  EXPECT_EQ(quantized_value(-0.8f, 0.5f), -1.0f);
  EXPECT_EQ(quantized_value(1e6f, 1.0f), float(kMaxQuantIndex));
  EXPECT_EQ(quantized_value(-1e6f, 1.0f), -float(kMaxQuantIndex));
  EXPECT_EQ(quantized_value(std::nanf(""), 0.5f), 0.0f);
  EXPECT_EQ(quantized_value(INFINITY, 0.5f), 0.0f);
  EXPECT_FALSE(std::signbit(quantized_value(-0.1f, 1.0f)));  // -0 is stored as +0
  EXPECT_EQ(quantized_value(1.0001f, 0.0f), 1.0f);            // step 0: fp16 alone
  EXPECT_EQ(quantized_value(0.3f, 0.0f), fp16(0.3f));
}

TEST(RateTerm, LaplaceBinBitsMatchTheDensityAndItsGradientFiniteDifferences) {
  for (double step : {0.01, 0.1, 1.0}) {
    for (double scale : {0.003, 0.05, 2.0}) {
      auto density = [&](double x) { return std::exp(-std::fabs(x) / scale) / (2 * scale); };
      for (double theta : {0.0, 0.2 * step, -0.3 * step, 0.49 * step, -0.51 * step, 0.7 * step, 3.2 * step,
                           -5.6 * step}) {
        SCOPED_TRACE(fmt::format("step {} scale {} theta {}", step, scale, theta));
        double d = 0;
        const double bits = laplace_bin_bits(theta, step, scale, &d);
        double mass = 0;  // Simpson's rule over the bin (kinks at 0 aside: the bin is split there)
        auto simpson = [&](double a, double b) {  // h at most scale / 40: the density's curvature
          const int n = 2 * int(std::min(200000.0, std::max(1000.0, 20 * (b - a) / scale)));
          const double h = (b - a) / n;
          double s = density(a) + density(b);
          for (int i = 1; i < n; ++i) s += density(a + i * h) * (i % 2 ? 4 : 2);
          return s * h / 3;
        };
        const double a = theta - step / 2, b = theta + step / 2;
        mass = a < 0 && b > 0 ? simpson(a, 0) + simpson(0, b) : simpson(a, b);
        if (mass > 1e-250) EXPECT_NEAR(bits, -std::log2(mass), 1e-6 * std::max(1.0, bits));  // else underflows
        const double h = 1e-6 * step;
        double dp, dm;
        const double fd =
            (laplace_bin_bits(theta + h, step, scale, &dp) - laplace_bin_bits(theta - h, step, scale, &dm)) / (2 * h);
        EXPECT_NEAR(d, fd, 1e-4 * std::max(1.0, std::fabs(fd)));
      }
      double total = 0;  // the bins at k * step partition the line
      for (int k = -20000; k <= 20000; ++k) {
        double d;
        total += std::exp2(-laplace_bin_bits(k * step, step, scale, &d));
      }
      EXPECT_NEAR(total, 1.0, 1e-9);
    }
  }
}

// add_rate_gradient adds weight * d bits / d theta to the segments with a step from first_segment on,
// with each segment's scale its mean |theta|, and returns their total bits.
TEST(RateTerm, GradientLandsOnTheQuantizedGridSegmentsOnly) {
  std::vector<ParamSegment> segs = {{5, 0.1f, {}}, {40000, 0.02f, {}}, {7, 0.0f, {}}, {30, 0.5f, {}}};
  std::vector<float> master(5 + 40000 + 7 + 30);
  for (size_t i = 0; i < master.size(); ++i) master[i] = float(std::sin(0.37 * double(i))) * (i < 40005 ? 0.05f : 1.f);
  std::vector<float> grads(master.size(), 1.0f);
  const double weight = 0.25;
  const double bits = add_rate_gradient(master, segs, 1, weight, grads.data());
  double expect_bits = 0;
  uint64_t off = 0;
  for (size_t k = 0; k < segs.size(); ++k) {
    double mean_abs = 0;
    for (uint64_t i = off; i < off + segs[k].count; ++i) mean_abs += std::fabs(master[i]) / double(segs[k].count);
    for (uint64_t i = off; i < off + segs[k].count; ++i) {
      double d = 0;
      if (k >= 1 && segs[k].step > 0) {
        expect_bits += laplace_bin_bits(master[i], segs[k].step, mean_abs, &d);
        ASSERT_NEAR(grads[i], 1.0 + weight * d, 1e-5 * (1 + std::fabs(weight * d))) << i;
      } else {
        ASSERT_EQ(grads[i], 1.0f) << i;  // the MLP (before first_segment) and raw segments are left alone
      }
    }
    off += segs[k].count;
  }
  EXPECT_NEAR(bits, expect_bits, 1e-9 * expect_bits);
}

// Rate-aware quantization-aware steps: the same run with the rate term leaves more of the grid's
// indices at zero (the term pulls parameters that do not pay for their bits into the zero bin), and the
// report says it ran.
TEST(RateTerm, RateAwareStepsZeroMoreOfTheGrid) {
  const std::string d = temp_dir("rate_aware");
  const Int3 dims{40, 40, 40};
  const std::string volume = write_volume(d, dims, "uint8");
  auto zero_share = [&](double weight) {
    TrainingSetup s = setup_for(d, volume, dims, "uint8");
    s.target_ratio = 8;
    s.qat_fraction = 0.5;
    s.rate_weight = weight;
    auto session = open_training_session(s);
    const Json summary = train_compact(*session, 40, 0, session->options().compact);
    EXPECT_EQ(summary["rate_weight"].get<double>(), weight);
    session->finish({.ssim = false});
    const Model m = load_model(s.session.output);
    const size_t first_grid = make_mlp_layout(m.net->config()).n_matrices;
    uint64_t off = 0, zeros = 0, n = 0;
    const std::vector<uint16_t> p = m.net->params_half();
    for (size_t k = 0; k < m.param_segments.size(); ++k) {
      const ParamSegment& seg = m.param_segments[k];
      if (k >= first_grid && seg.step > 0)
        for (uint64_t i = off; i < off + seg.count; ++i, ++n) zeros += half_to_float(p[i]) == 0.0f;
      off += seg.count;
    }
    return double(zeros) / double(n);
  };
  const double plain = zero_share(0), rate_aware = zero_share(3);
  EXPECT_GT(rate_aware, plain + 0.05) << plain << " " << rate_aware;
}

// The split of a file between the network and its residuals (config_sizing.h), in closed form: a tenth
// for the network, the config's where that is at least 32 KiB, else (config auto) the small preset's of
// at least 4 KiB, and none where the network would take over half of the file.
TEST(RateControl, ResidualSplitGivesTheNetworkATenthAndAFloor) {
  const uint64_t bonsai = 16u << 20, voxels = 16u << 20, wmag = 91u * 91 * 91 * 4;
  ResidualSplit s = residual_network_split(bonsai, voxels, 32, true, nullptr);
  EXPECT_DOUBLE_EQ(s.network_ratio, 320.0);
  EXPECT_FALSE(s.small_network);
  s = residual_network_split(bonsai, voxels, 128, true, nullptr);  // a tenth is 13 KB: the small network
  EXPECT_DOUBLE_EQ(s.network_ratio, 1280.0);
  EXPECT_TRUE(s.small_network);
  s = residual_network_split(bonsai, voxels, 128, false, nullptr);  // the user's config: 32 KiB, a quarter
  EXPECT_DOUBLE_EQ(s.network_ratio, double(bonsai) / 32768);
  EXPECT_FALSE(s.small_network);
  s = residual_network_split(wmag, wmag / 4, 64, true, nullptr);  // a tenth is 4.7 KB: its own
  EXPECT_DOUBLE_EQ(s.network_ratio, 640.0);
  EXPECT_TRUE(s.small_network);
  s = residual_network_split(wmag, wmag / 4, 128, true, nullptr);  // a tenth is 2.4 KB: its own
  EXPECT_DOUBLE_EQ(s.network_ratio, 1280.0);
  s = residual_network_split(wmag, wmag / 4, 256, true, nullptr);  // a tenth is 1.2 KB: 2 KiB, 17 %
  EXPECT_DOUBLE_EQ(s.network_ratio, double(wmag) / 2048);
  EXPECT_TRUE(s.small_network);
  EXPECT_EQ(residual_network_split(wmag, wmag / 4, 64, false, nullptr).network_ratio, 0.0);  // 32 KiB: 70 %
  EXPECT_EQ(residual_network_split(wmag, wmag / 4, 1024, true, nullptr).network_ratio, 0.0);  // 2 KiB > a half
}

// --target-ratio alone on a volume where the file has bits to spare (1 bit per voxel): --residuals auto
// trains a smaller network and spends the rest of the file on residuals (wavelet or voxel).
// The file still meets the target within 5 %, the bound holds at every voxel, the decode is better than
// the network alone (which renders) and than a network of the whole file; --residuals off keeps the
// whole file for the network.
TEST(RateControl, ResidualsFillTheFileBesideASmallerNetwork) {
  const std::string d = temp_dir("rate_residuals");
  const Int3 dims{64, 64, 64};
  const std::string volume = write_volume(d, dims, "float32");
  auto train = [&](const std::string& residuals) {
    TrainingSetup s = setup_for(d, volume, dims, "float32");
    s.target_ratio = 8;
    s.residuals = residuals;
    s.session.output = d + "/" + residuals + ".vnr";
    auto session = open_training_session(s);
    train_compact(*session, 20, 0, session->options().compact);
    return std::make_pair(session->options().compact, session->finish({.ssim = false}));
  };
  const uint64_t target = dims.count() * 4 / 8;
  const auto [with_opts, with] = train("auto");
  EXPECT_EQ(with_opts.file_bytes, target);
  EXPECT_LE(double(with_opts.target_bytes), 0.5 * double(target));
  EXPECT_LE(with.model_bytes, target);
  // Within 5 % of the target, or under it where the residuals reach fp32 precision (wavelets do on this
  // smooth field: nothing is left to spend the rest on).
  if (with.psnr < 120) EXPECT_GE(double(with.model_bytes), 0.95 * double(target)) << with.psnr;
  ASSERT_TRUE(with.report.contains("error_bound")) << with.report.dump();
  const Json& b = with.report["error_bound"];
  EXPECT_EQ(b["chosen_by"], "target_ratio");
  EXPECT_TRUE(b["holds"].get<bool>());
  EXPECT_LE(with.max_abs_error_original, b["max_error"].get<double>());
  EXPECT_LT(with.report["network_psnr"].get<double>() + 3, with.psnr);
  const Model loaded = load_model(d + "/auto.vnr");
  ASSERT_TRUE(loaded.residuals.has_value());
  EXPECT_DOUBLE_EQ(loaded.residuals->bound, b["max_error_normalised"].get<double>());

  const auto [off_opts, off] = train("off");
  EXPECT_EQ(off_opts.file_bytes, 0u);
  EXPECT_EQ(off_opts.target_bytes, target);
  EXPECT_FALSE(off.report.contains("error_bound"));
  EXPECT_LE(off.model_bytes, target);
  EXPECT_GT(with.psnr, off.psnr + 3) << with.psnr << " " << off.psnr;

  TrainingSetup bad = setup_for(d, volume, dims, "float32");
  bad.residuals = "some";
  EXPECT_NE(one_line_error_of([&] { check_training_setup(bad); }).find("--residuals must be auto or off"),
            std::string::npos);
}

// --learn-steps: the steps train over the quantization-aware part and the file still meets the target
// within 5 %; its segments' steps are no longer the plan's shape times one scale.
TEST(RateControl, LearnedStepsMeetTheTarget) {
  const std::string d = temp_dir("rate_learned");
  const Int3 dims{40, 40, 40};
  const std::string volume = write_volume(d, dims, "uint8");
  TrainingSetup s = setup_for(d, volume, dims, "uint8");
  s.target_ratio = 8;
  s.residuals = "off";
  s.qat_fraction = 0.5;
  s.learn_steps = true;
  auto session = open_training_session(s);
  std::vector<std::string> notes;
  train_compact(*session, 60, 0, session->options().compact, [&](const std::string& m) { notes.push_back(m); });
  session->finish({.ssim = false});
  const double target = double(dims.count()) / 8;
  EXPECT_NEAR(double(file_size(s.session.output)), target, 0.05 * target);
  bool noted = false;
  for (const std::string& m : notes) noted |= m.rfind("learned steps:", 0) == 0;
  EXPECT_TRUE(noted);
  EXPECT_FALSE(load_model(s.session.output).param_segments.empty());
}
