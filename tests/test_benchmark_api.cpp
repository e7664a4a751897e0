// The benchmarking API (include/vnr/benchmark.h): sane, positive rates for a tiny volume in a fraction
// of a second per call, clear errors for bad options, and `vnr bench train|infer` writing the report
// keys it always wrote.
#include <gtest/gtest.h>
#include <chrono>
#include <cmath>
#include <set>
#include "test_support.h"
#include "vnr/benchmark.h"
#include "vnr/progress.h"
#include "vnr/vnr.h"
#include "vnr/train/model_io.h"

using namespace vnr;
using namespace vnr::test;

namespace {

Volume tiny_volume() {
  const Int3 d{16, 12, 8};
  std::vector<float> v(d.count());
  for (size_t i = 0; i < v.size(); ++i) v[i] = std::sin(0.21f * float(i));
  return volume_from_array(v.data(), d);
}

ModelConfig tiny_config() { return ModelConfig::from_json(preset_config("tiny")); }

BenchOptions quick_options() {
  BenchOptions o;
  o.seconds = 0.05;
  o.batch = 1024;
  o.mlp_seconds = 0.02;
  return o;
}

// What every CPU result holds, training or not.
void expect_sane_cpu_result(const BenchResult& r, const BenchOptions& o, uint64_t n_params) {
  EXPECT_EQ(r.device, Device::Cpu);
  EXPECT_EQ(r.batch, o.batch);
  EXPECT_EQ(r.n_params, n_params);
  ASSERT_GE(r.batch_seconds.size(), 3u);
  for (double s : r.batch_seconds) EXPECT_GT(s, 0);
  EXPECT_GT(r.samples_per_second, 0);
  EXPECT_NEAR(r.samples_per_second, double(r.batch) / (r.ms_median / 1e3), 1e-6 * r.samples_per_second);
  EXPECT_LE(r.ms_min, r.ms_median);
  EXPECT_LE(r.ms_median, r.ms_max);
  EXPECT_GT(r.mlp_flops_per_sample, 0);
  EXPECT_GT(r.mlp_gflops, 0);
  EXPECT_GT(r.threads, 0);
  EXPECT_FALSE(r.simd.empty());
  EXPECT_TRUE(r.gpu.empty());
  EXPECT_EQ(r.peak_gpu_memory_bytes, 0u);
}

double seconds_of(const std::function<void()>& fn) {
  const auto t0 = std::chrono::steady_clock::now();
  fn();
  return seconds_since(t0);
}

}  // namespace

TEST(BenchmarkApi, TrainingGivesPositiveRatesAndThreePhases) {
  const Volume vol = tiny_volume();
  BenchOptions o = quick_options();
  o.precision = "fp32";
  int progress_calls = 0, finished_calls = 0;
  o.progress = [&](double seconds, bool finished) {
    EXPECT_GE(seconds, 0);
    ++(finished ? finished_calls : progress_calls);
  };
  BenchResult r;
  const double took = seconds_of([&] { r = benchmark_training(vol, tiny_config(), o); });
  EXPECT_LT(took, 5.0);  // well under a second on an idle machine; the bound allows a loaded one
  const Model m = create_model(tiny_config(), vol);
  expect_sane_cpu_result(r, o, m.net->n_params());
  EXPECT_TRUE(r.training);
  EXPECT_EQ(r.mlp_flops_per_sample, 3.0 * m.net->flops_forward_per_sample());
  EXPECT_EQ(r.precision, Precision::FP32);
  ASSERT_EQ(r.phases.size(), 3u);
  for (const BenchPhase& p : r.phases) {
    EXPECT_FALSE(p.key.empty());
    EXPECT_FALSE(p.name.empty());
    EXPECT_GE(p.ms, 0);
  }
  EXPECT_EQ(r.phases[2].key, "optimizer");
  EXPECT_EQ(progress_calls, int(r.batch_seconds.size()));
  EXPECT_EQ(finished_calls, 1);
}

TEST(BenchmarkApi, InferenceGivesPositiveRatesInTheAskedPrecision) {
  const Volume vol = tiny_volume();
  BenchOptions o = quick_options();
  o.precision = "fp32";
  BenchResult r;
  const double took = seconds_of([&] { r = benchmark_inference(vol, tiny_config(), o); });
  EXPECT_LT(took, 5.0);
  const Model m = create_model(tiny_config(), vol);
  expect_sane_cpu_result(r, o, m.net->n_params());
  EXPECT_FALSE(r.training);
  EXPECT_EQ(r.mlp_flops_per_sample, m.net->flops_forward_per_sample());
  EXPECT_EQ(r.precision, Precision::FP32);
  EXPECT_TRUE(r.phases.empty());
  EXPECT_EQ(r.resident_batch, 0);

  // A caller's model: its inference precision is set from the options.
  Model own = create_model(tiny_config(), vol, 3);
  BenchResult ro = benchmark_inference(own, o);
  EXPECT_EQ(own.net->inference_precision(), Precision::FP32);
  EXPECT_GT(ro.samples_per_second, 0);
}

TEST(BenchmarkApi, BadOptionsFailWithOneLine) {
  const Volume vol = tiny_volume();
  auto expect_one_line = [](const std::string& msg, const std::string& needle) {
    EXPECT_HAS(msg, needle);
    EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  };
  BenchOptions o = quick_options();
  o.batch = 0;
  expect_one_line(error_of([&] { benchmark_training(vol, tiny_config(), o); }), "batch");
  expect_one_line(error_of([&] { benchmark_inference(vol, tiny_config(), o); }), "batch");
  o = quick_options();
  o.seconds = -1;
  expect_one_line(error_of([&] { benchmark_inference(vol, tiny_config(), o); }), "seconds");
  o.seconds = std::nan("");
  expect_one_line(error_of([&] { benchmark_training(vol, tiny_config(), o); }), "seconds");
  o = quick_options();
  o.precision = "fp16";
  expect_one_line(error_of([&] { benchmark_inference(vol, tiny_config(), o); }), "fp16");
  expect_one_line(error_of([&] { benchmark_training(vol, tiny_config(), o); }), "fp16");
}

// `vnr bench train|infer --report`: exactly the keys the command wrote before the benchmarking API.
TEST(BenchmarkApi, CliReportKeysAreUnchanged) {
  const std::string d = temp_dir("vnr_cli");
  ASSERT_EQ(run("synth marschner-lobb --dims 16,16,16 --force -o " + d + "/b.json").code, 0);
  const std::set<std::string> cpu_keys = {
      "mode",     "device",         "config",       "samples_per_second",   "batch",
      "batches",  "ms_median",      "ms_min",       "ms_max",               "mlp_flops_per_sample",
      "gflops_end_to_end", "mlp_gflops", "threads", "simd", "precision", "n_params"};
  for (const std::string what : {"train", "infer"}) {
    const std::string report = d + "/" + what + ".json";
    Result r = run("bench " + what + " " + d + "/b.json --config tiny --seconds 0.05 --batch 1024 --device cpu "
                   "--report " + report);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_HAS(r.out, what + " tiny");
    EXPECT_HAS(r.out, "M samples/s (median of ");
    EXPECT_HAS(r.out, "MLP kernels alone");
    const Json j = parse_json_file(report);
    std::set<std::string> keys;
    for (auto it = j.begin(); it != j.end(); ++it) keys.insert(it.key());
    std::set<std::string> expected = cpu_keys;
    if (what == "train") expected.insert("phase_ms");
    EXPECT_EQ(keys, expected);
    EXPECT_EQ(j["mode"], what);
    EXPECT_EQ(j["device"], "cpu");
    EXPECT_EQ(j["batch"], 1024);
    EXPECT_GT(j["samples_per_second"].get<double>(), 0);
    if (what == "train") {
      EXPECT_HAS(r.out, "phases (median ms): ");
      EXPECT_EQ(j["phase_ms"].size(), 3u);
      EXPECT_TRUE(j["phase_ms"].contains("optimizer"));
    }
  }
}
