// Time-varying volumes: the file-list descriptor, synthetic series, warm-started per-timestep
// training, continuous training (fixed learning rate, switching, recovery) and `vnr train
// --timesteps` end to end.
#include <gtest/gtest.h>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <string>
#include <vector>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/json.h"
#include "vnr/model_config.h"
#include "vnr/train/model_io.h"
#include "vnr/train/series.h"
#include "vnr/volume/volume.h"
#include "vnr/volume_writer.h"
#include "test_support.h"

using namespace vnr;
using namespace vnr::test;

namespace {

void write_floats(const std::string& path, const std::vector<float>& v) {
  std::ofstream f(path, std::ios::binary);
  f.write(reinterpret_cast<const char*>(v.data()), std::streamsize(v.size() * sizeof(float)));
}

std::string bytes_of(const std::string& path) { return read_file(path); }

RawOptions at(int t) {
  RawOptions o;
  o.timestep = t;
  return o;
}

Volume load_t(const std::string& json, int t) { return load_volume(describe_volume(json, at(t))); }

Json small_config() { return preset_config("small"); }

Model fresh_model(const Json& config, uint32_t seed = 7) {
  Model m;
  m.net = std::make_unique<Network>(config);
  m.net->init_params(seed);
  return m;
}

}  // namespace

// ------------------------------------------------------------------------------------------------
// The file-list descriptor: {"file": ["a.raw", "b.raw", ...], "dims": [x, y, z], ...}.

TEST(Series, FileListDescriptor) {
  TmpDir tmp;
  const std::string d = tmp.str();
  const Int3 dims{4, 3, 2};
  const size_t n = dims.count();
  for (int t = 0; t < 3; ++t) {
    std::vector<float> v(n);
    for (size_t i = 0; i < n; ++i) v[i] = float(100 * t + int(i));
    write_floats(d + "/f" + std::to_string(t) + ".raw", v);
  }
  write_file_atomic(d + "/list.json",
                    R"({"file": ["f0.raw", "f1.raw", "f2.raw"], "dims": [4, 3, 2], "dtype": "float32",
                        "value_range": [0, 300]})");
  VolumeDesc d0 = describe_volume(d + "/list.json");
  EXPECT_EQ(d0.n_timesteps, 3);
  EXPECT_EQ(d0.timestep, 0);
  EXPECT_EQ(d0.path, d + "/f0.raw");
  VolumeDesc d2 = describe_volume(d + "/list.json", at(2));
  EXPECT_EQ(d2.path, d + "/f2.raw");
  EXPECT_EQ(d2.offset, 0u);  // each file holds one frame
  Volume v2 = load_volume(d2);
  EXPECT_EQ(v2.lo, 0);
  EXPECT_EQ(v2.hi, 300);
  for (size_t i = 0; i < n; ++i) EXPECT_FLOAT_EQ(v2.data[i], float((200 + i) / 300.0));
  EXPECT_HAS(error_of([&] { describe_volume(d + "/list.json", at(3)); }), "timestep 3 out of range");

  // A matching 4th dim is accepted; a list of one is a plain volume.
  write_file_atomic(d + "/list4.json", R"({"file": ["f0.raw", "f1.raw", "f2.raw"], "dims": [4, 3, 2, 3], "dtype": "float32"})");
  EXPECT_EQ(describe_volume(d + "/list4.json").n_timesteps, 3);
  write_file_atomic(d + "/one.json", R"({"file": ["f1.raw"], "dims": [4, 3, 2], "dtype": "float32"})");
  VolumeDesc one = describe_volume(d + "/one.json");
  EXPECT_EQ(one.n_timesteps, 1);
  EXPECT_FLOAT_EQ(load_volume(one).data[n - 1], 1.0f);

  // Errors, each naming what is wrong.
  write_floats(d + "/short.raw", std::vector<float>(n - 1, 0.f));
  write_file_atomic(d + "/bad_size.json", R"({"file": ["f0.raw", "short.raw"], "dims": [4, 3, 2], "dtype": "float32"})");
  std::string m = error_of([&] { describe_volume(d + "/bad_size.json"); });
  EXPECT_HAS(m, "same size");
  EXPECT_HAS(m, "short.raw");
  EXPECT_HAS(m, "timestep 1");
  write_file_atomic(d + "/missing.json", R"({"file": ["f0.raw", "nope.raw"], "dims": [4, 3, 2], "dtype": "float32"})");
  m = error_of([&] { describe_volume(d + "/missing.json"); });
  EXPECT_HAS(m, "nope.raw");
  EXPECT_HAS(m, "does not exist");
  write_file_atomic(d + "/empty.json", R"({"file": [], "dims": [4, 3, 2], "dtype": "float32"})");
  EXPECT_HAS(error_of([&] { describe_volume(d + "/empty.json"); }), "empty array");
  write_file_atomic(d + "/nonstr.json", R"({"file": ["f0.raw", 3], "dims": [4, 3, 2], "dtype": "float32"})");
  EXPECT_HAS(error_of([&] { describe_volume(d + "/nonstr.json"); }), "must be a string");
  write_file_atomic(d + "/t4.json", R"({"file": ["f0.raw", "f1.raw"], "dims": [4, 3, 2, 3], "dtype": "float32"})");
  EXPECT_HAS(error_of([&] { describe_volume(d + "/t4.json"); }), "lists 2 files");
  // All files the wrong size for the dims: the selected one is reported with expected bytes.
  write_file_atomic(d + "/dims.json", R"({"file": ["f0.raw", "f1.raw"], "dims": [4, 3, 3], "dtype": "float32"})");
  EXPECT_HAS(error_of([&] { describe_volume(d + "/dims.json"); }), "expected");
}

// ------------------------------------------------------------------------------------------------
// Synthetic series.

TEST(Series, SynthSeriesFramesDifferSmoothlyAndAreDeterministic) {
  TmpDir tmp;
  const std::string d = tmp.str();
  const Int3 dims{16, 12, 10};
  const size_t n = dims.count();
  synth_series("noise", dims, 3, d + "/a.json", 5);
  synth_series("noise", dims, 3, d + "/b.json", 5);
  synth_series("noise", dims, 3, d + "/c.json", 5, /*file_list=*/true);
  synth_volume("noise", dims, d + "/v.json", 5);
  EXPECT_EQ(bytes_of(d + "/a.raw"), bytes_of(d + "/b.raw"));  // deterministic
  const std::string all = bytes_of(d + "/a.raw");
  ASSERT_EQ(all.size(), 3 * n * 4);
  EXPECT_EQ(all.substr(0, n * 4), bytes_of(d + "/v.raw"));  // timestep 0 is synth_volume's volume
  for (int t = 0; t < 3; ++t)  // the file list holds the same frames
    EXPECT_EQ(bytes_of(d + "/c_t000" + std::to_string(t) + ".raw"), all.substr(size_t(t) * n * 4, n * 4)) << t;

  VolumeDesc desc = describe_volume(d + "/a.json");
  EXPECT_EQ(desc.n_timesteps, 3);
  EXPECT_EQ(describe_volume(d + "/c.json").n_timesteps, 3);
  std::vector<Volume> f;
  for (int t = 0; t < 3; ++t) f.push_back(load_t(d + "/a.json", t));
  for (int t = 0; t < 3; ++t) {
    EXPECT_EQ(f[t].lo, f[0].lo);  // one value range for the whole series
    EXPECT_EQ(f[t].hi, f[0].hi);
  }
  // Consecutive frames differ, but by much less than the field varies (it drifts smoothly).
  auto mean_abs = [&](const Volume& a, const Volume& b) {
    double s = 0;
    for (size_t i = 0; i < n; ++i) s += std::fabs(double(a.data[i]) - double(b.data[i]));
    return s / double(n);
  };
  double mean = 0;
  for (size_t i = 0; i < n; ++i) mean += f[0].data[i];
  mean /= double(n);
  double spread = 0;
  for (size_t i = 0; i < n; ++i) spread += std::fabs(f[0].data[i] - mean);
  spread /= double(n);
  const double d01 = mean_abs(f[0], f[1]), d02 = mean_abs(f[0], f[2]);
  EXPECT_GT(d01, 1e-3);
  EXPECT_LT(d01, 0.6 * spread);
  EXPECT_GT(d02, d01);  // further apart in time, further apart in value

  // synth_series_value is the stored voxel value.
  std::vector<float> raw(3 * n);
  std::memcpy(raw.data(), all.data(), all.size());
  for (int t = 0; t < 3; ++t)
    for (int64_t i : {int64_t(0), int64_t(77), int64_t(n - 1)}) {
      int64_t x = i % dims.x, y = (i / dims.x) % dims.y, z = i / (dims.x * dims.y);
      float u[3] = {float((x + 0.5) / dims.x), float((y + 0.5) / dims.y), float((z + 0.5) / dims.z)};
      EXPECT_EQ(synth_series_value("noise", t, u[0], u[1], u[2], 5), raw[size_t(t) * n + size_t(i)]);
    }
  // Marschner-Lobb series too.
  synth_series("marschner-lobb", {8, 8, 8}, 2, d + "/ml.json");
  EXPECT_EQ(describe_volume(d + "/ml.json").n_timesteps, 2);
  EXPECT_HAS(error_of([&] { synth_series("noise", dims, 0, d + "/z.json"); }), "timesteps");
  EXPECT_HAS(error_of([&] { synth_series("noise", dims, 2, d + "/z.raw"); }), ".json");
}

TEST(Series, TimestepSelection) {
  EXPECT_EQ(parse_timestep_selection("all", 3), (std::vector<int>{0, 1, 2}));
  EXPECT_EQ(parse_timestep_selection("1-2", 3), (std::vector<int>{1, 2}));
  EXPECT_EQ(parse_timestep_selection("2,0", 3), (std::vector<int>{2, 0}));
  EXPECT_EQ(parse_timestep_selection("0-1, 3", 4), (std::vector<int>{0, 1, 3}));
  EXPECT_EQ(parse_timestep_selection("4", 5), (std::vector<int>{4}));
  EXPECT_HAS(error_of([] { parse_timestep_selection("0-5", 3); }), "timestep 5 out of range");
  EXPECT_HAS(error_of([] { parse_timestep_selection("3", 3); }), "0..2");
  EXPECT_HAS(error_of([] { parse_timestep_selection("2-1", 3); }), "descending");
  EXPECT_HAS(error_of([] { parse_timestep_selection("1,0-1", 3); }), "twice");
  for (const char* bad : {"", "x", "1-", "-1", "1,,2", "1.5", "al"})
    EXPECT_HAS(error_of([&] { parse_timestep_selection(bad, 3); }), "--timesteps expects") << bad;
  EXPECT_EQ(timestep_model_name(7), "t0007.vnr");
  EXPECT_EQ(timestep_model_name(12345), "t12345.vnr");
}

// ------------------------------------------------------------------------------------------------
// Per-timestep training with warm start.

TEST(Series, WarmStartBeatsColdStartWithTheSameSteps) {
  TmpDir tmp;
  const std::string d = tmp.str();
  synth_series("noise", {32, 32, 32}, 2, d + "/s.json", 3);
  FrameLoader load = [&](int t) { return load_t(d + "/s.json", t); };
  SeriesOptions o;
  o.train.batch = 8192;
  o.steps = 40;
  o.init_seed = 7;
  std::vector<Model> saved;
  auto keep = [&](const TimestepResult&, const Model& m) {
    Model c;
    c.net = std::make_unique<Network>(m.net->config_json());
    c.net->set_params(m.net->params().data(), m.net->params().size());
    c.training = m.training;
    c.macrocells = m.macrocells;
    saved.push_back(std::move(c));
  };
  Model warm = fresh_model(small_config(), 7);
  std::vector<TimestepResult> w = train_series(warm, {0, 1}, load, o, {}, keep);
  o.warm_start = false;
  Model cold = fresh_model(small_config(), 7);
  std::vector<TimestepResult> c = train_series(cold, {0, 1}, load, o, {});
  ASSERT_EQ(w.size(), 2u);
  ASSERT_EQ(c.size(), 2u);
  EXPECT_FALSE(w[0].warm_started);
  EXPECT_TRUE(w[1].warm_started);
  EXPECT_FALSE(c[1].warm_started);
  EXPECT_EQ(w[0].eval.psnr, c[0].eval.psnr);  // the first timestep is the same run
  EXPECT_EQ(w[1].steps, 40);
  EXPECT_EQ(c[1].steps, 40);
  // After the same 40 steps, the warm-started model fits timestep 1 far better.
  EXPECT_GT(w[1].eval.psnr, c[1].eval.psnr + 2.0) << w[1].eval.psnr << " vs " << c[1].eval.psnr;
  EXPECT_LT(w[1].loss_history[0], c[1].loss_history[0]);
  EXPECT_LT(w[1].final_loss, c[1].final_loss);
  // Each model carries its own timestep's summary and online macro-cells.
  ASSERT_EQ(saved.size(), 2u);
  for (int t = 0; t < 2; ++t) {
    EXPECT_EQ(saved[size_t(t)].training["timestep"], t);
    ASSERT_TRUE(saved[size_t(t)].macrocells.has_value());
  }
  EXPECT_NE(saved[0].macrocells->lo, saved[1].macrocells->lo);
  EXPECT_NE(saved[0].net->params(), saved[1].net->params());
}

TEST(Series, FailureMidwayKeepsFinishedModels) {
  TmpDir tmp;
  const std::string d = tmp.str();
  synth_series("noise", {16, 16, 16}, 3, d + "/s.json");
  FrameLoader load = [&](int t) {
    if (t == 1) fail("frame {} is unreadable", t);
    return load_t(d + "/s.json", t);
  };
  SeriesOptions o;
  o.train.batch = 4096;
  o.steps = 5;
  std::vector<int> done;
  Model m = fresh_model(small_config());
  std::string msg = error_of([&] {
    train_series(m, {0, 1, 2}, load, o, {}, [&](const TimestepResult& r, const Model& mm) {
      save_model(d + "/" + timestep_model_name(r.timestep), mm);
      done.push_back(r.timestep);
    });
  });
  EXPECT_HAS(msg, "frame 1 is unreadable");
  EXPECT_EQ(done, std::vector<int>{0});
  Model back = load_model(d + "/t0000.vnr");
  EXPECT_EQ(back.training["timestep"], 0);
  EXPECT_FALSE(file_exists(d + "/t0001.vnr"));
}

// ------------------------------------------------------------------------------------------------
// Continuous training.

namespace {

// Two very different frames: a smooth field and its inverse.
std::vector<Volume> inverse_pair(Int3 dims) {
  std::vector<float> a(dims.count()), b(dims.count());
  for (int64_t z = 0, i = 0; z < dims.z; ++z)
    for (int64_t y = 0; y < dims.y; ++y)
      for (int64_t x = 0; x < dims.x; ++x, ++i) {
        float v = 0.5f + 0.4f * std::sin(0.3f * float(x)) * std::cos(0.2f * float(y) + 0.1f * float(z));
        a[size_t(i)] = v;
        b[size_t(i)] = 1.0f - v;
      }
  std::vector<Volume> f;
  f.push_back(make_volume(dims, a));
  f.push_back(make_volume(dims, b));
  return f;
}

Json decaying_config() {
  Json c = small_config();
  c["optimizer"]["decay_start"] = 0;
  c["optimizer"]["decay_interval"] = 1;
  c["optimizer"]["decay_base"] = 0.9;
  return c;
}

}  // namespace

TEST(Series, ContinuousKeepsTheLearningRateAndSwitchesTarget) {
  const Int3 dims{24, 24, 24};
  std::vector<Volume> frames = inverse_pair(dims);
  FrameLoader load = [&](int t) { return make_volume(dims, std::vector<float>(frames[t].data.begin(), frames[t].data.end())); };
  // The config decays every step: a per-timestep CpuTrainer's rate drops fast...
  {
    Model m = fresh_model(decaying_config());
    CpuTrainer tr(*m.net, std::make_shared<InCoreSampler>(frames[0]), TrainOptions{4096, 1});
    for (int i = 0; i < 5; ++i) tr.step();
    EXPECT_LT(tr.current_learning_rate(), 0.6f * 0.005f);
  }
  // ...continuous training removes the decay: the rate is constant for the whole run.
  const int64_t N = 40;
  ContinuousOptions o;
  o.train.batch = 4096;
  o.switch_every = N;
  o.probe_every = 5;
  Model m = fresh_model(decaying_config());
  std::vector<WindowResult> windows;
  ContinuousResult r = train_continuous(m, {0, 1}, load, o, {}, [&](const WindowResult& w, const Model& mm) {
    windows.push_back(w);
    EXPECT_EQ(mm.training["timestep"], w.timestep);
    EXPECT_TRUE(mm.macrocells.has_value());
  });
  ASSERT_EQ(r.windows.size(), 2u);
  ASSERT_EQ(windows.size(), 2u);
  ASSERT_EQ(r.learning_rate_history.size(), size_t(2 * N));
  for (float lr : r.learning_rate_history) EXPECT_EQ(lr, 0.005f);
  EXPECT_EQ(r.learning_rate, 0.005f);
  EXPECT_FALSE(r.config.decay.enabled);
  EXPECT_FALSE(m.net->config().decay.enabled);  // the saved models say so too
  EXPECT_EQ(r.probe_voxels, int64_t(dims.count()));  // 24^3 < 2^16: every voxel

  // The target switches exactly after N steps: the loss jumps at step N (0-based), the probes at the
  // switch step compare the same network against both timesteps.
  ASSERT_EQ(r.loss_history.size(), size_t(2 * N));
  EXPECT_GT(r.loss_history[N], 2.5f * r.loss_history[N - 1]);
  for (int64_t s = 1; s < N; ++s) EXPECT_LT(r.loss_history[s], 3 * r.loss_history[s - 1] + 1e-3) << s;
  const WindowResult& w1 = r.windows[1];
  EXPECT_TRUE(w1.has_switch);
  EXPECT_FALSE(r.windows[0].has_switch);
  EXPECT_EQ(w1.first_step, N);
  EXPECT_EQ(w1.from_timestep, 0);
  int at_switch = 0;
  for (const ProbePoint& p : r.probes)
    if (p.step == N) {
      ++at_switch;
      EXPECT_EQ(p.psnr, p.timestep == 0 ? w1.psnr_before : w1.psnr_after);
    }
  EXPECT_EQ(at_switch, 2);
  EXPECT_LT(w1.psnr_after, w1.psnr_before - 3);
  // Probes: at 0, every 5 steps, per window.
  EXPECT_EQ(r.probes.size(), size_t(2 * (N / 5 + 1)));
  // The recovery count is the first probe of the new window at or above psnr_before.
  std::vector<ProbePoint> mine;
  for (const ProbePoint& p : r.probes)
    if (p.timestep == 1) mine.push_back(p);
  int64_t expect = -1;
  for (const ProbePoint& p : mine)
    if (p.psnr >= w1.psnr_before) {
      expect = p.step - N;
      break;
    }
  EXPECT_EQ(w1.recovery_steps, expect);
  // At the end the network represents the new timestep, not the old one.
  PsnrProbe probe(dims, 1 << 16, 1);
  EXPECT_GT(probe.psnr(*m.net, frames[1]), probe.psnr(*m.net, frames[0]) + 3);
  EXPECT_NEAR(probe.psnr(*m.net, frames[1]), w1.psnr_end, 1e-9);  // all voxels: the probe is the full PSNR
  EXPECT_NEAR(w1.eval.psnr, w1.psnr_end, 1e-3);

  // An explicit learning rate replaces the config's and stays fixed too.
  o.learning_rate = 0.01f;
  Model m2 = fresh_model(decaying_config());
  ContinuousResult r2 = train_continuous(m2, {0, 1}, load, o);
  for (float lr : r2.learning_rate_history) EXPECT_EQ(lr, 0.01f);
  o.switch_every = 0;
  EXPECT_HAS(error_of([&] { train_continuous(m2, {0, 1}, load, o); }), "positive switch interval");
}

TEST(Series, RecoveryCount) {
  // The rule on constructed probes: switch at step 100, probes every 10 steps.
  std::vector<ProbePoint> p = {{90, 0, 30.0}, {100, 1, 20.0}, {110, 1, 24.0}, {120, 1, 26.0}, {130, 1, 25.0}};
  EXPECT_EQ(steps_to_recover(p, 100, 25.0), 20);
  EXPECT_EQ(steps_to_recover(p, 100, 26.0), 20);   // reaching the threshold exactly counts
  EXPECT_EQ(steps_to_recover(p, 100, 20.0), 0);    // already there at the switch
  EXPECT_EQ(steps_to_recover(p, 100, 26.5), -1);   // never: not recovered
  EXPECT_EQ(steps_to_recover(p, 100, 29.0), -1);   // the probe before the switch does not count

  // Identical timesteps: the switch changes nothing, so the network has recovered at once (0 steps)
  // and the PSNR after the switch is exactly the PSNR before it.
  const Int3 dims{20, 20, 20};
  std::vector<Volume> frames = inverse_pair(dims);
  FrameLoader same = [&](int) { return make_volume(dims, std::vector<float>(frames[0].data.begin(), frames[0].data.end())); };
  ContinuousOptions o;
  o.train.batch = 4096;
  o.switch_every = 20;
  o.probe_every = 4;
  o.probe_voxels = 1000;  // a subset
  Model m = fresh_model(small_config());
  ContinuousResult r = train_continuous(m, {0, 1, 2}, same, o);
  ASSERT_EQ(r.windows.size(), 3u);
  EXPECT_EQ(r.probe_voxels, 1000);
  for (size_t k = 1; k < 3; ++k) {
    EXPECT_EQ(r.windows[k].psnr_after, r.windows[k].psnr_before);
    EXPECT_EQ(r.windows[k].recovery_steps, 0);
    EXPECT_EQ(r.windows[k].recovery_seconds, 0.0);
  }
  // An inverted timestep, short windows, a probe every step: the count is the rule applied to the
  // window's own probes.
  FrameLoader inv = [&](int t) { return make_volume(dims, std::vector<float>(frames[t].data.begin(), frames[t].data.end())); };
  o.switch_every = 4;
  o.probe_every = 1;
  Model m2 = fresh_model(small_config());
  ContinuousResult r2 = train_continuous(m2, {0, 1}, inv, o);
  // With a tolerance as large as the drop, it is recovered at once.
  o.recovery_tolerance_db = 1000;
  Model m3 = fresh_model(small_config());
  ContinuousResult r3 = train_continuous(m3, {0, 1}, inv, o);
  ASSERT_EQ(r2.windows.size(), 2u);
  std::vector<ProbePoint> second;
  for (const ProbePoint& q : r2.probes)
    if (q.timestep == 1) second.push_back(q);
  ASSERT_EQ(second.size(), 5u);  // steps 4 (the switch), 5, 6, 7, 8
  EXPECT_EQ(second[0].psnr, r2.windows[1].psnr_after);
  EXPECT_EQ(r2.windows[1].recovery_steps, steps_to_recover(second, 4, r2.windows[1].psnr_before));
  EXPECT_EQ(r3.windows[1].recovery_steps, 0);
}

// ------------------------------------------------------------------------------------------------
// `vnr train SERIES --timesteps ...`

TEST(SeriesCli, PerTimestepModelsThatEvalAccepts) {
  TmpDir tmp;
  const std::string d = tmp.str();
  ASSERT_EQ(run("synth noise --dims 24,24,24 --timesteps 3 -o " + d + "/s.json").code, 0);
  Result t = run("train " + d + "/s.json --timesteps all -o " + d + "/out --config small --steps 40 --batch 8192 -q");
  ASSERT_EQ(t.code, 0) << t.err;
  EXPECT_HAS(t.out, "t0002");
  Json rep = parse_json_file(d + "/out/series.json");
  ASSERT_EQ(rep["rows"].size(), 3u);
  EXPECT_EQ(rep["complete"], true);
  EXPECT_EQ(rep["mode"], "per_timestep");
  EXPECT_EQ(rep["precision"], "fp32");  // --precision auto keeps the small config's 16-wide MLP in fp32
  for (int k = 0; k < 3; ++k) {
    const Json& row = rep["rows"][size_t(k)];
    std::string model = d + "/out/t000" + std::to_string(k) + ".vnr";
    EXPECT_EQ(row["timestep"], k);
    EXPECT_EQ(row["model"], model);
    EXPECT_EQ(row["warm_start"], k > 0);
    EXPECT_EQ(row["steps"], 40);
    Model m = load_model(model);
    EXPECT_EQ(m.training["timestep"], k);
    // `vnr eval` against the same timestep gives the row's PSNR (fp16 parameters vs fp32 training copy).
    Result e = run("eval " + model + " " + d + "/s.json --timestep " + std::to_string(k) + " --no-ssim --report " + d +
                   "/e.json");
    ASSERT_EQ(e.code, 0) << e.err;
    EXPECT_NEAR(parse_json_file(d + "/e.json")["psnr"].get<double>(), row["psnr"].get<double>(), 0.1);
  }
  // Each model fits its own timestep better than another one.
  ASSERT_EQ(run("eval " + d + "/out/t0000.vnr " + d + "/s.json --timestep 2 --no-ssim --report " + d + "/e2.json").code, 0);
  EXPECT_LT(parse_json_file(d + "/e2.json")["psnr"].get<double>(), rep["rows"][0]["psnr"].get<double>() - 1);

  // A file-list series, a subset in a given order, a report elsewhere.
  ASSERT_EQ(run("synth marschner-lobb --dims 20,20,20 --timesteps 3 --file-list -o " + d + "/ml.json").code, 0);
  EXPECT_TRUE(file_exists(d + "/ml_t0002.raw"));
  t = run("train " + d + "/ml.json --timesteps 2,0 -o " + d + "/sub --config small --steps 10 --batch 4096 -q --no-ssim --report " +
          d + "/sub.json");
  ASSERT_EQ(t.code, 0) << t.err;
  Json sub = parse_json_file(d + "/sub.json");
  ASSERT_EQ(sub["rows"].size(), 2u);
  EXPECT_EQ(sub["rows"][0]["timestep"], 2);
  EXPECT_EQ(sub["rows"][1]["timestep"], 0);
  EXPECT_TRUE(file_exists(d + "/sub/t0002.vnr"));
  EXPECT_TRUE(file_exists(d + "/sub/t0000.vnr"));
  EXPECT_FALSE(file_exists(d + "/sub/t0001.vnr"));
  EXPECT_FALSE(file_exists(d + "/sub/series.json"));
}

TEST(SeriesCli, ContinuousReportsRecovery) {
  TmpDir tmp;
  const std::string d = tmp.str();
  ASSERT_EQ(run("synth noise --dims 20,20,20 --timesteps 3 -o " + d + "/s.json").code, 0);
  Result t = run("train " + d + "/s.json --timesteps all --continuous --switch-every 20 -o " + d +
                 "/out --config small --batch 4096 -q --no-ssim");
  ASSERT_EQ(t.code, 0) << t.err;
  EXPECT_HAS(t.out, "recovered");
  EXPECT_HAS(t.out, "t0000 -> t0001");
  EXPECT_HAS(t.out, "t0001 -> t0002");
  Json rep = parse_json_file(d + "/out/series.json");
  EXPECT_EQ(rep["mode"], "continuous");
  EXPECT_EQ(rep["precision"], "fp32");
  ASSERT_EQ(rep["rows"].size(), 3u);
  EXPECT_TRUE(rep["rows"][0]["switch"].is_null());
  for (int k = 1; k < 3; ++k) {
    const Json& sw = rep["rows"][size_t(k)]["switch"];
    EXPECT_EQ(sw["from"], k - 1);
    for (const char* key : {"psnr_before", "psnr_after", "recovered", "recovery_steps", "recovery_seconds"})
      EXPECT_TRUE(sw.contains(key)) << key;
    EXPECT_EQ(rep["rows"][size_t(k)]["first_step"], 20 * k);
  }
  EXPECT_EQ(rep["loss_history"].size(), 60u);
  EXPECT_EQ(rep["probe_voxels"], 8000);
  for (int k = 0; k < 3; ++k) EXPECT_TRUE(file_exists(d + "/out/t000" + std::to_string(k) + ".vnr"));
  Model m = load_model(d + "/out/t0002.vnr");
  EXPECT_EQ(m.training["continuous"], true);
  EXPECT_FALSE(m.net->config().decay.enabled);
}

// Compact and error-bounded series: every timestep's file meets --target-ratio, every timestep's decode
// holds --max-rel-error against that timestep, and warm starts continue from unquantized parameters.
TEST(SeriesCli, CompactAndErrorBoundedModelsPerTimestep) {
  TmpDir tmp;
  const std::string d = tmp.str();
  ASSERT_EQ(run("synth noise --dims 24,24,24 --timesteps 3 -o " + d + "/s.json").code, 0);
  const std::string base = "train " + d + "/s.json --timesteps all --config small --steps 40 --batch 4096 -q --no-ssim ";
  Result t = run(base + "--target-ratio 16 -o " + d + "/compact");
  ASSERT_EQ(t.code, 0) << t.err;
  const double budget = 24.0 * 24 * 24 * 4 / 16;  // float32 frames
  for (int k = 0; k < 3; ++k) {
    const std::string model = d + "/compact/t000" + std::to_string(k) + ".vnr";
    const double bytes = double(file_size(model));
    EXPECT_LE(bytes, budget) << model;
    EXPECT_GE(bytes, 0.95 * budget) << model;
    EXPECT_FALSE(load_model(model).param_segments.empty());
  }
  t = run(base + "--max-rel-error 1e-2 -o " + d + "/bounded");
  ASSERT_EQ(t.code, 0) << t.err;
  const Json rep = parse_json_file(d + "/bounded/series.json");
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(rep["rows"][size_t(k)]["error_bound"]["holds"], true);
    Result e = run("eval " + d + "/bounded/t000" + std::to_string(k) + ".vnr " + d + "/s.json --timestep " +
                   std::to_string(k) + " --no-ssim --report " + d + "/e.json");
    ASSERT_EQ(e.code, 0) << e.err;
    const Json ev = parse_json_file(d + "/e.json");
    EXPECT_LE(ev["max_abs_error"].get<double>(), 1e-2 + 1e-9) << ev.dump();  // normalised units
  }
  expect_error("train " + d + "/s.json --timesteps all --continuous --switch-every 5 --max-error 1 -o " + d + "/o4",
               "not with --continuous");
}

TEST(SeriesCli, ClearErrors) {
  TmpDir tmp;
  const std::string d = tmp.str();
  ASSERT_EQ(run("synth noise --dims 8,8,8 -o " + d + "/one.json").code, 0);
  ASSERT_EQ(run("synth noise --dims 8,8,8 --timesteps 3 -o " + d + "/s.json").code, 0);
  const std::string base = "train " + d + "/s.json --config small --steps 2 --batch 256 -q ";
  expect_error("train " + d + "/one.json --timesteps all -o " + d + "/o1 --config small", "single timestep");
  expect_error(base + "--timesteps 0-5 -o " + d + "/o2", "timestep 5 out of range");
  expect_error(base + "--timesteps 1,1 -o " + d + "/o2", "twice");
  write_file_atomic(d + "/afile", "x");
  expect_error(base + "--timesteps all -o " + d + "/afile", "existing file");
  expect_error(base + "--timesteps all -o " + d + "/m.vnr", "directory");
  expect_error("train " + d + "/s.json --timesteps all --continuous -o " + d + "/o3", "--switch-every");
  expect_error(base + "--timesteps all --switch-every 5 -o " + d + "/o3", "needs --continuous");
  expect_error("train " + d + "/s.json --timesteps all --continuous --switch-every 5 --steps 10 -o " + d + "/o3",
               "do not apply");
  expect_error(base + "--timesteps all --timestep 1 -o " + d + "/o3", "--timestep");
  expect_error("synth noise --dims 8,8,8 --file-list -o " + d + "/fl.json", "--file-list needs --timesteps");
  EXPECT_FALSE(file_exists(d + "/o2"));  // nothing is created before the arguments are checked
  EXPECT_FALSE(file_exists(d + "/o3"));
}

TEST(SeriesCli, FailureMidwayKeepsTheFirstModel) {
  TmpDir tmp;
  const std::string d = tmp.str();
  const Int3 dims{12, 12, 12};
  std::vector<float> v(dims.count());
  for (size_t i = 0; i < v.size(); ++i) v[i] = float(i % 97) / 97.f;
  write_floats(d + "/f0.raw", v);
  v[100] = std::numeric_limits<float>::quiet_NaN();  // timestep 1 cannot be loaded (NaN without --nan)
  write_floats(d + "/f1.raw", v);
  write_file_atomic(d + "/s.json", R"({"file": ["f0.raw", "f1.raw"], "dims": [12, 12, 12], "dtype": "float32"})");
  Result r = run("train " + d + "/s.json --timesteps all -o " + d + "/out --config small --steps 5 --batch 1024 -q");
  EXPECT_NE(r.code, 0);
  EXPECT_EQ(count_lines(r.err), 1) << r.err;
  EXPECT_HAS(r.err, "NaN");
  EXPECT_HAS(r.err, "f1.raw");
  EXPECT_HAS(r.err, "1 finished model kept");
  Model m = load_model(d + "/out/t0000.vnr");  // on disk and loadable
  EXPECT_EQ(m.training["timestep"], 0);
  EXPECT_FALSE(file_exists(d + "/out/t0001.vnr"));
  Json rep = parse_json_file(d + "/out/series.json");
  EXPECT_EQ(rep["complete"], false);
  EXPECT_EQ(rep["rows"].size(), 1u);

  // A truncated file in a file list is caught before any training.
  write_floats(d + "/f1.raw", std::vector<float>(dims.count() - 5, 0.f));
  expect_error("train " + d + "/s.json --timesteps all -o " + d + "/out2 --config small --steps 5 --batch 1024 -q",
               "same size");
  EXPECT_FALSE(file_exists(d + "/out2/t0000.vnr"));
}
