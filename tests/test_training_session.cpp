// TrainingSession (vnr/trainer.h): the one training loop. Runs by steps and by seconds; a stop requested
// from a callback or another thread ends it after the current step; pause/resume; checkpoints every N
// steps that load back to the same parameters; the error policy; the report's keys; CPU results equal
// to driving CpuTrainer by hand, bit for bit; the same Trainer interface on the GPU.
#include <gtest/gtest.h>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <thread>
#include "vnr/error.h"
#include "vnr/cuda/cuda.h"
#include "vnr/trainer.h"
#include "vnr/train/make_trainer.h"
#include "vnr/train/session.h"
#include "test_support.h"

using namespace vnr;
using namespace vnr::test;

namespace {

Json small_config() { return small_hash_config(12, 16, 1); }

// A model of a small volume and a CPU session training it.
struct Fixture {
  Volume vol = synth(Int3{16, 12, 10});
  Model model;
  std::unique_ptr<TrainingSession> session;
  explicit Fixture(SessionOptions so = {}, std::shared_ptr<Sampler> sampler = nullptr) {
    model = create_model(ModelConfig::from_json(small_config()), vol.dims, DType::Float32, 0, 1, 5);
    if (!sampler) sampler = std::make_shared<InCoreSampler>(vol);
    session = std::make_unique<TrainingSession>(
        model, make_trainer(Device::Cpu, *model.net, sampler, &vol, TrainOptions{1024, 7}), so);
  }
};

bool same_params(const Network& a, const Network& b) {
  return a.params().size() == b.params().size() &&
         std::memcmp(a.params().data(), b.params().data(), a.params().size() * sizeof(float)) == 0;
}

// Throws from the given step on (the data "went away").
class FailingSampler : public Sampler {
public:
  FailingSampler(const Volume& v, uint64_t fail_at) : inner_(v), fail_at_(fail_at) {}
  void begin_step(uint64_t step) override {
    if (step >= fail_at_) fail("the volume file went away");
  }
  void sample(uint64_t seed, uint64_t step, uint64_t chunk, int n, float* x, float* y, float* z,
              float* target) const override {
    inner_.sample(seed, step, chunk, n, x, y, z, target);
  }

private:
  InCoreSampler inner_;
  uint64_t fail_at_;
};

// A CPU trainer that says it is asynchronous (as the GPU's is), so the session groups its steps; it
// records the size of every group.
class GroupingTrainer final : public Trainer {
public:
  explicit GroupingTrainer(std::unique_ptr<Trainer> inner) : inner_(std::move(inner)) {}
  std::vector<int64_t> groups;
  Device device() const override { return inner_->device(); }
  bool asynchronous() const override { return true; }
  void run(int64_t n) override {
    groups.push_back(n);
    inner_->run(n);
  }
  float last_loss() const override { return inner_->last_loss(); }
  std::vector<float> losses_from(uint64_t first) const override { return inner_->losses_from(first); }
  uint64_t steps_done() const override { return inner_->steps_done(); }
  float current_learning_rate() const override { return inner_->current_learning_rate(); }
  void set_learning_rate_multiplier(float m) override { inner_->set_learning_rate_multiplier(m); }
  void enable_online_ranges(Int3 dims, int cell) override { inner_->enable_online_ranges(dims, cell); }
  bool has_online_ranges() const override { return inner_->has_online_ranges(); }
  ValueRangeGrid online_ranges() const override { return inner_->online_ranges(); }
  void download() override { inner_->download(); }
  Network& network() override { return inner_->network(); }
  int64_t batch() const override { return inner_->batch(); }
  uint32_t seed() const override { return inner_->seed(); }
  std::optional<Precision> mlp_precision() const override { return inner_->mlp_precision(); }
  std::vector<PhaseTime> last_step_phases() const override { return inner_->last_step_phases(); }

private:
  std::unique_ptr<Trainer> inner_;
};

}  // namespace

// An asynchronous trainer's groups of steps grow, but never cross a multiple of sync_every steps of the
// run (nor a checkpoint), so side work sees each of those steps (what time series' probes rely on).
TEST(TrainingSession, GroupsOfStepsEndAtEverySyncStep) {
  Volume vol = synth(Int3{16, 12, 10});
  Model model = create_model(ModelConfig::from_json(small_config()), vol.dims, DType::Float32, 0, 1, 5);
  auto inner = make_trainer(Device::Cpu, *model.net, std::make_shared<InCoreSampler>(vol), &vol, TrainOptions{1024, 7});
  auto grouping = std::make_unique<GroupingTrainer>(std::move(inner));
  GroupingTrainer* g = grouping.get();
  SessionOptions so;
  so.sync_every = 5;
  TrainingSession session(model, std::move(grouping), so);
  std::vector<int64_t> seen;
  session.add_side_work([&](const TrainingProgress& p) { seen.push_back(p.step); });
  session.run(3);  // the second run counts from its own start
  seen.clear();
  g->groups.clear();
  EXPECT_EQ(session.run(23), 23);
  int64_t done = 0;
  for (int64_t k : g->groups) {
    EXPECT_EQ(done / 5, (done + k - 1) / 5) << "group of " << k << " from " << done;
    done += k;
  }
  EXPECT_EQ(done, 23);
  for (int64_t s : {5, 10, 15, 20, 23}) EXPECT_NE(std::find(seen.begin(), seen.end(), 3 + s), seen.end()) << s;
  EXPECT_GT(*std::max_element(g->groups.begin(), g->groups.end()), 1);  // it did group
  EXPECT_EQ(session.steps_done(), 26);
}

// The cool-down: over the last 20 % of a declared budget the rate falls linearly, min(1, (1 - p) / 0.2)
// at progress p = steps done / budget before the step, across run() calls; with cooldown 0, or once
// the budget is spent, the config's rate.
TEST(TrainingSession, CooldownLowersTheRateLinearlyAtTheBudgetsEnd) {
  for (double cooldown : {0.2, 0.0}) {
    SessionOptions so;
    so.cooldown = cooldown;
    Fixture f(so);
    const float base = f.session->trainer().current_learning_rate();
    std::vector<float> lr;
    f.session->add_step_callback([&](const TrainingProgress&) { lr.push_back(f.session->trainer().current_learning_rate()); });
    f.session->set_budget(100, 0);
    f.session->run(60);
    f.session->run(40);  // the same budget, a second call (compact training's two phases)
    ASSERT_EQ(lr.size(), 100u);
    for (int i = 0; i < 100; ++i) {
      const double want = cooldown > 0 ? std::min(1.0, (1.0 - i / 100.0) / cooldown) : 1.0;
      EXPECT_NEAR(lr[size_t(i)], base * want, 1e-6 * base) << "step " << i;
    }
    f.session->run(3);  // past the budget
    EXPECT_FLOAT_EQ(lr.back(), base);
  }
  // Without a budget (the viewer's slices, continuous series) nothing changes.
  Fixture f;
  std::vector<float> lr;
  f.session->add_step_callback([&](const TrainingProgress&) { lr.push_back(f.session->trainer().current_learning_rate()); });
  f.session->run(10);
  for (float v : lr) EXPECT_EQ(v, lr.front());
}

TEST(TrainingSession, RunsNStepsAndStops) {
  Fixture f;
  std::vector<int64_t> seen;
  f.session->add_step_callback([&](const TrainingProgress& p) {
    seen.push_back(p.step);
    EXPECT_TRUE(std::isfinite(p.loss));
    EXPECT_GT(p.samples_per_second, 0);
    EXPECT_GE(p.elapsed, 0);
  });
  EXPECT_EQ(f.session->run(5), 5);
  EXPECT_EQ(f.session->run(3), 3);
  EXPECT_EQ(f.session->steps_done(), 8);
  EXPECT_EQ(seen, (std::vector<int64_t>{1, 2, 3, 4, 5, 6, 7, 8}));
  EXPECT_EQ(f.session->trainer().steps_done(), 8u);
  EXPECT_EQ(f.session->trainer().losses().size(), 8u);
  const std::vector<float> all = f.session->trainer().losses();  // a poller's new ones are the tail
  EXPECT_EQ(f.session->trainer().losses_from(5), std::vector<float>(all.begin() + 5, all.end()));
  EXPECT_TRUE(f.session->trainer().losses_from(8).empty());
  EXPECT_TRUE(f.session->trainer().losses_from(20).empty());
  EXPECT_EQ(f.session->step_seconds().size(), 8u);
  EXPECT_EQ(f.session->last_loss(), f.session->trainer().losses().back());
  const float loss = f.session->step();
  EXPECT_EQ(loss, f.session->trainer().last_loss());
  EXPECT_EQ(f.session->steps_done(), 9);
}

TEST(TrainingSession, RunsBySeconds) {
  Fixture f;
  const int64_t n = f.session->run(-1, 0.3);
  EXPECT_GT(n, 0);
  EXPECT_GE(f.session->training_seconds(), 0.3);
  EXPECT_LT(f.session->training_seconds(), 30.0);
  EXPECT_FALSE(f.session->stop_requested());
}

TEST(TrainingSession, StopFromACallbackEndsAfterTheCurrentStep) {
  Fixture f;
  f.session->add_step_callback([&](const TrainingProgress& p) {
    if (p.step == 3) f.session->request_stop();
  });
  EXPECT_EQ(f.session->run(100), 3);
  EXPECT_TRUE(f.session->stop_requested());
  EXPECT_EQ(f.session->run(100), 0) << "a stopped session stays stopped";
}

TEST(TrainingSession, StopFromAnotherThread) {
  Fixture f;
  std::atomic<int64_t> steps{0};
  f.session->add_step_callback([&](const TrainingProgress& p) { steps.store(p.step); });
  std::thread stopper([&] {
    while (steps.load() < 2) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    f.session->request_stop();
  });
  const int64_t n = f.session->run(-1);  // no limit: only the stop ends it
  stopper.join();
  EXPECT_GE(n, 2);
  EXPECT_EQ(n, steps.load()) << "the callback saw every step";
}

TEST(TrainingSession, PauseAndResume) {
  Fixture f;
  std::atomic<int64_t> steps{0};
  f.session->add_step_callback([&](const TrainingProgress& p) {
    steps.store(p.step);
    if (p.step == 3) f.session->pause();  // pauses before step 4
  });
  double wall = 0;
  std::thread runner([&] {
    const auto t0 = std::chrono::steady_clock::now();
    f.session->run(10);
    wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  });
  while (steps.load() < 3) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  std::this_thread::sleep_for(std::chrono::milliseconds(150));
  EXPECT_TRUE(f.session->paused());
  EXPECT_EQ(steps.load(), 3) << "no step while paused";
  f.session->resume();
  runner.join();
  EXPECT_EQ(steps.load(), 10);
  EXPECT_LE(f.session->training_seconds(), wall - 0.14) << "the pause is not training time";

  // A stop ends a paused run.
  Fixture g;
  g.session->pause();
  std::thread stopper([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    g.session->request_stop();
  });
  EXPECT_EQ(g.session->run(10), 0);
  stopper.join();
}

TEST(TrainingSession, SideWorkIsNotTrainingTime) {
  Fixture f;
  int calls = 0;
  f.session->add_side_work([&](const TrainingProgress&) {
    ++calls;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  });
  const auto t0 = std::chrono::steady_clock::now();
  f.session->run(3);
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(calls, 3);
  EXPECT_GE(f.session->side_seconds(), 0.3);
  EXPECT_LE(f.session->training_seconds(), wall - 0.29);
}

TEST(TrainingSession, CheckpointsEveryNStepsLoadBackToTheSameParameters) {
  const std::string d = temp_dir("session_ckpt");
  SessionOptions so;
  so.output = d + "/ck.vnr";
  so.checkpoint_every = 4;
  Fixture f(so);
  std::vector<int64_t> written_at;
  f.session->add_step_callback([&](const TrainingProgress& p) {
    if (p.step % 4 == 0) save_model(d + "/mine.vnr", f.model);  // the same parameters, by hand
    if (std::filesystem::exists(so.output)) {
      const int64_t at = load_model(so.output).training["steps"].get<int64_t>();
      if (written_at.empty() || written_at.back() != at) written_at.push_back(at);
    }
  });
  f.session->run(10);
  EXPECT_EQ(written_at, (std::vector<int64_t>{4, 8}));
  Model ck = load_model(so.output), mine = load_model(d + "/mine.vnr");
  EXPECT_TRUE(ck.training["checkpoint"].get<bool>());
  EXPECT_EQ(ck.training["steps"].get<int64_t>(), 8);
  EXPECT_EQ(ck.training["sampler"], "incore");
  EXPECT_EQ(ck.training["device"], "cpu");
  EXPECT_TRUE(same_params(*ck.net, *mine.net));
  ASSERT_TRUE(ck.macrocells.has_value() == f.session->trainer().has_online_ranges());
}

TEST(TrainingSession, AnErrorMidTrainingSavesTheModelSoFar) {
  const std::string d = temp_dir("session_error");
  Volume vol = synth(Int3{16, 12, 10});
  SessionOptions so;
  so.output = d + "/err.vnr";
  Fixture f(so, std::make_shared<FailingSampler>(vol, 3));
  const std::string e = error_of([&] { f.session->run(10); });
  EXPECT_NE(e.find("the volume file went away"), std::string::npos) << e;
  EXPECT_NE(e.find("the model after 3 steps was saved to"), std::string::npos) << e;
  Model m = load_model(so.output);
  EXPECT_EQ(m.training["steps"].get<int64_t>(), 3);
  EXPECT_EQ(m.training["error"], "the volume file went away");

  // Without an output (or before any step) the error passes through unchanged.
  Fixture g(SessionOptions{}, std::make_shared<FailingSampler>(vol, 0));
  EXPECT_EQ(error_of([&] { g.session->run(10); }), "the volume file went away");
}

TEST(TrainingSession, CpuSessionEqualsDrivingCpuTrainerByHand) {
  Fixture f;
  f.session->trainer().enable_online_ranges(f.vol.dims, 4);
  f.session->run(6);
  f.session->run(-1, 0.0001);  // a time-limited run: at least one step
  const int64_t n = f.session->steps_done();

  Model by_hand = create_model(ModelConfig::from_json(small_config()), f.vol.dims, DType::Float32, 0, 1, 5);
  CpuTrainer tr(*by_hand.net, std::make_shared<InCoreSampler>(f.vol), TrainOptions{1024, 7});
  tr.enable_online_ranges(f.vol.dims, 4);
  for (int64_t i = 0; i < n; ++i) tr.step();
  EXPECT_TRUE(same_params(*f.model.net, *by_hand.net));
  EXPECT_EQ(f.session->trainer().losses(), tr.loss_history());
  const ValueRangeGrid a = f.session->trainer().online_ranges(), b = tr.online_ranges();
  ASSERT_EQ(a.count(), b.count());
  for (int64_t c = 0; c < a.count(); ++c) EXPECT_EQ(a.empty(c), b.empty(c));
}

TEST(TrainingSession, OpenFinishAndReportKeys) {
  const std::string d = temp_dir("session_open");
  Volume vol = synth(Int3{16, 12, 10});
  std::string bytes(vol.data.size() * sizeof(float), '\0');
  std::memcpy(bytes.data(), vol.data.data(), bytes.size());
  write_bytes(d + "/v.raw", bytes);
  TrainingSetup s;
  s.volume = d + "/v.raw";
  s.raw.dims = vol.dims;
  s.raw.dtype = "float32";
  s.config = "small";
  s.batch = 4096;
  s.seed = 3;
  s.device = "cpu";
  s.session.output = d + "/v.vnr";
  std::vector<std::string> lines;
  auto session = open_training_session(s, [&](const std::string& l) { lines.push_back(l); });
  ASSERT_FALSE(lines.empty());
  EXPECT_EQ(lines[0].rfind("volume " + s.volume + ": 16x12x10 float32", 0), 0u) << lines[0];
  EXPECT_EQ(session->trainer().device(), Device::Cpu);
  EXPECT_FALSE(session->io_wait_seconds().has_value());  // in core: no reads to wait for
  session->run(5);
  const TrainingResult r = session->finish({.ssim = false});
  EXPECT_EQ(r.steps, 5);
  EXPECT_TRUE(std::isfinite(r.psnr));
  EXPECT_FALSE(r.ssim.has_value());
  for (const char* key : {"steps", "seconds", "seconds_per_step", "median_step_seconds", "step_seconds",
                          "samples_per_second", "final_loss", "psnr", "ssim", "evaluation", "max_abs_error",
                          "n_params", "model_bytes", "volume_bytes", "compression_ratio", "batch", "threads",
                          "sampler", "memory_budget", "loss_history", "device", "precision", "preview_seconds",
                          "config"})
    EXPECT_TRUE(r.report.contains(key)) << key;
  EXPECT_EQ(r.report["evaluation"]["method"], "full");
  EXPECT_EQ(r.report["loss_history"].size(), 5u);
  Model m = load_model(s.session.output);
  EXPECT_EQ(m.training["steps"].get<int64_t>(), 5);
  EXPECT_FALSE(m.training["interrupted"].get<bool>());
  EXPECT_EQ(m.training["psnr"].get<double>(), r.psnr);

  // Out of core, the session reports the sampler's waits for reads, as the report's out_of_core does.
  s.data.sampler = "outofcore";
  s.session.output = d + "/ooc.vnr";
  auto ooc = open_training_session(s);
  ooc->run(3);
  ASSERT_TRUE(ooc->io_wait_seconds().has_value());
  EXPECT_GE(*ooc->io_wait_seconds(), 0.0);
  const TrainingResult ro = ooc->finish({.evaluate = false});
  EXPECT_EQ(ro.report["out_of_core"]["io_wait_seconds"].get<double>(), *ooc->io_wait_seconds());
}

TEST(TrainingSession, GpuSessionUsesTheSameTrainerInterface) {
  Volume vol = synth(Int3{16, 12, 10});
  Model model = create_model(ModelConfig::from_json(small_config()), vol.dims, DType::Float32, 0, 1, 5);
  if (cuda::devices().empty()) {
    EXPECT_THROW(make_trainer(Device::Cuda, *model.net, nullptr, &vol, TrainOptions{1024, 7}), Error);
    GTEST_SKIP() << "no CUDA device: " << cuda::no_device_reason();
  }
  std::unique_ptr<Trainer> t = make_trainer(Device::Cuda, *model.net, nullptr, &vol, TrainOptions{1024, 7});
  EXPECT_EQ(t->device(), Device::Cuda);
  EXPECT_TRUE(t->asynchronous());
  EXPECT_FALSE(t->mlp_precision().has_value());
  TrainingSession session(model, std::move(t));
  session.trainer().enable_online_ranges(vol.dims, 4);
  EXPECT_EQ(session.run(20), 20);
  EXPECT_EQ(session.trainer().steps_done(), 20u);
  EXPECT_EQ(session.trainer().losses().size(), 20u);
  EXPECT_TRUE(std::isfinite(session.last_loss()));
  session.finish();  // downloads the parameters and the online ranges into the model
  EXPECT_EQ(model.training["device"], "cuda");
  EXPECT_TRUE(model.macrocells.has_value());
}

// TrainingSetup's JSON: the defaults of the struct, every key read back, unknown keys and bad values
// refused with one line naming them.
TEST(TrainingSetup, JsonRoundTripsAndRefusesWhatItDoesNotKnow) {
  EXPECT_EQ(TrainingSetup::from_json(Json::object()).to_json(), TrainingSetup{}.to_json());
  const Json j = {{"volume", "v.json"},       {"config", {{"encoding", {{"otype", "HashGrid"}}}}},
                  {"target_ratio", 64},       {"residuals", "off"},        {"bits_per_param", 3},
                  {"qat_fraction", 0.2},      {"rate_weight", 0.5},        {"batch", 8192},
                  {"seed", 5},                {"device", "cpu"},           {"precision", "fp32"},
                  {"macrocell_size", 8},      {"steps", 300},              {"sampler", "outofcore"},
                  {"memory_budget", "16MiB"}, {"blocks", 64},              {"block_dims", {16, 8, 8}},
                  {"grid_lr_scale", "auto"},  {"output", "m.vnr"},         {"checkpoint_every", 100},
                  {"cooldown", 0.1},          {"max_rel_error", 0.01},     {"dims", {40, 30, 20}},
                  {"dtype", "uint16"},        {"endian", "big"},           {"offset", 12},
                  {"range", {0, 4095}},       {"nan", "clamp"}};
  const TrainingSetup s = TrainingSetup::from_json(j);
  ASSERT_TRUE(s.config_json.has_value());
  EXPECT_EQ((*s.config_json)["encoding"]["otype"], "HashGrid");
  EXPECT_EQ(s.data.memory_budget, uint64_t(16) << 20);
  EXPECT_TRUE(*s.data.block_dims == (Int3{16, 8, 8}));
  EXPECT_TRUE(*s.raw.dims == (Int3{40, 30, 20}));
  EXPECT_EQ(*s.raw.range_hi, 4095.0);
  EXPECT_EQ(s.load.non_finite, NonFinitePolicy::Clamp);
  EXPECT_EQ(s.session.cooldown, 0.1);
  EXPECT_EQ(s.session.error_bound.max_rel_error, 0.01);
  EXPECT_EQ(TrainingSetup::from_json(s.to_json()).to_json(), s.to_json());

  auto error_of_setup = [](const Json& bad) {
    try {
      TrainingSetup::from_json(bad);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  std::string msg = error_of_setup(Json{{"learning_rate", 1e-3}});
  EXPECT_NE(msg.find("unknown key 'learning_rate'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("target_ratio"), std::string::npos) << msg;  // the allowed list
  for (const auto& [bad, needle] : std::vector<std::pair<Json, std::string>>{
           {{{"batch", 100}}, "batch must be a positive multiple of 256"},
           {{{"cooldown", 2}}, "cooldown must be in [0, 1]"},
           {{{"seed", "one"}}, "'seed' must be a number"},
           {{{"config", 3}}, "'config' must be"},
           {{{"range", {5, 1}}}, "'range' must be [lo, hi]"},
           {{{"nan", "skip"}}, "nan policy 'skip'"},
           {{{"memory_budget", 0}}, "'memory_budget' must be positive"}}) {
    msg = error_of_setup(bad);
    EXPECT_NE(msg.find(needle), std::string::npos) << bad.dump() << " -> " << msg;
  }
  // JSON (and Python) name the keys; the command line's check names its options.
  EXPECT_EQ(error_of_setup(Json{{"qat_fraction", 2}}).find("--"), std::string::npos);
  TrainingSetup cli;
  cli.qat_fraction = 2;
  EXPECT_THROW(
      try { check_training_setup(cli); } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("--qat-fraction must be in [0, 1]"), std::string::npos) << e.what();
        throw;
      },
      Error);
}
