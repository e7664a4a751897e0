// The GPU's training and multi-brick paths beyond one in-memory volume (ctest label `gpu`): the GPU
// trainer fed by a host sampler (the CPU trainer's samples) against the GPU sampling its own copy; the
// out-of-core sampler feeding the GPU; time series on the GPU, per timestep and continuously (one
// optimizer across timesteps); a multi-brick model decoded and rendered on the GPU against the CPU;
// quantization-aware and rate-aware training of compact models on the GPU against the CPU.
// Without a CUDA device every test reports itself skipped with the reason.
#include <gtest/gtest.h>
#include <cmath>
#include <filesystem>
#include <fmt/format.h>
#include "bricks_test_support.h"
#include "test_support.h"
#include "vnr/cuda/cuda.h"
#include "vnr/model.h"
#include "vnr/core/half.h"
#include "vnr/nn/mlp_layout.h"
#include "vnr/model_config.h"
#include "vnr/renderer.h"
#include "vnr/train/make_trainer.h"
#include "vnr/train/model_io.h"
#include "vnr/train/rate_control.h"
#include "vnr/train/series.h"
#include "vnr/train/session.h"
#include "vnr/volume_writer.h"

using namespace vnr;
using namespace vnr::test;

namespace {

#define REQUIRE_GPU()                                                                              \
  do {                                                                                             \
    if (cuda::devices().empty()) GTEST_SKIP() << "no CUDA device: " << cuda::no_device_reason(); \
  } while (0)

std::unique_ptr<Network> fresh(const char* preset, uint32_t seed = 3) {
  auto net = std::make_unique<Network>(preset_config(preset));
  net->init_params(seed);
  return net;
}

double image_psnr(const Image& a, const Image& b) { return compare_images(a, b).psnr; }

}  // namespace

// The same samples two ways: drawn on the GPU from its copy of the volume, and drawn on the host by
// InCoreSampler (bit-identical coordinates and targets) and copied: the first step's loss is the same
// (another batch would differ by ~1 %); later ones drift apart only through the order of the atomic sums
// (the grid gradient's), which training amplifies to a few per cent, so their means are compared.
TEST(GpuHostFed, HostSamplesGiveTheInCoreLosses) {
  REQUIRE_GPU();
  const Volume vol = synth(Int3{40, 36, 32});
  auto a = fresh("paper"), b = fresh("paper");
  const TrainOptions o{16384, 9};
  auto resident = make_trainer(Device::Cuda, *a, nullptr, &vol, o);
  auto fed = make_trainer(Device::Cuda, *b, std::make_shared<InCoreSampler>(vol), nullptr, o);
  resident->run(60);
  fed->run(60);
  const std::vector<float> la = resident->losses(), lb = fed->losses();
  ASSERT_EQ(la.size(), 60u);
  ASSERT_EQ(lb.size(), 60u);
  EXPECT_NEAR(lb[0], la[0], 1e-5 * la[0]);
  double ma = 0, mb = 0;
  for (size_t i = la.size() - 10; i < la.size(); ++i) ma += la[i], mb += lb[i];
  EXPECT_NEAR(mb, ma, 0.1 * ma) << "mean loss of the last 10 steps";
  EXPECT_LT(lb.back(), 0.5f * lb.front());
}

// `vnr train --sampler outofcore --device cuda`: the out-of-core sampler feeds the GPU, which reaches the
// CPU's quality after the same steps on the same samples.
TEST(GpuHostFed, OutOfCoreSamplerTrainsOnTheGpu) {
  REQUIRE_GPU();
  TmpDir dir("gpu_ooc");
  synth_volume("marschner-lobb", Int3{64, 64, 64}, dir / "v.json");
  auto run = [&](const char* device) {
    TrainingSetup s;
    s.volume = dir / "v.json";
    s.config = "small";
    s.batch = 16384;
    s.seed = 4;
    s.device = device;
    s.data.sampler = "outofcore";
    s.data.memory_budget = 1 << 20;  // the volume (1 MiB) does not fit: blocks are streamed
    s.session.output = dir / (std::string(device) + ".vnr");
    auto session = open_training_session(s);
    EXPECT_EQ(session->trainer().device(), std::string(device) == "cuda" ? Device::Cuda : Device::Cpu);
    session->run(400);
    const TrainingResult r = session->finish({.ssim = false, .eval_samples = 1 << 18});  // out of core: a sampled evaluation
    return r.psnr;
  };
  const double gpu = run("cuda"), cpu = run("cpu");
  std::printf("out-of-core, 400 steps: PSNR %.2f dB on the GPU, %.2f on the CPU\n", gpu, cpu);
  EXPECT_GT(gpu, cpu - 1.5);
  EXPECT_GT(gpu, 25.0);
}

// Time series on the GPU: per timestep (each frame copied to the GPU, warm-started) and continuously (one
// optimizer for the run: the learning rate stays, the loss jumps at the switch, the probes follow).
TEST(GpuSeries, PerTimestepAndContinuousTrainOnTheGpu) {
  REQUIRE_GPU();
  const Int3 dims{24, 24, 24};
  std::vector<Volume> frames;
  frames.push_back(synth(dims));
  frames.push_back(synth(dims));
  for (float& v : frames[1].data) v = 1.0f - v;
  FrameLoader load = [&](int t) {
    Volume v;
    v.dims = dims;
    v.data.assign(frames[size_t(t)].data.begin(), frames[size_t(t)].data.end());
    return v;
  };
  {
    Model m;
    m.net = fresh("small");
    SeriesOptions o;
    o.train.batch = 4096;
    o.steps = 200;
    o.device = Device::Cuda;
    std::vector<TimestepResult> r = train_series(m, {0, 1}, load, o, {});
    ASSERT_EQ(r.size(), 2u);
    for (const TimestepResult& t : r) {
      std::printf("per timestep on the GPU: t%d %.2f dB\n", t.timestep, t.eval.psnr);
      EXPECT_GT(t.eval.psnr, 25.0);
      EXPECT_EQ(t.loss_history.size(), 200u);
    }
  }
  const int64_t N = 40;
  ContinuousOptions o;
  o.train.batch = 4096;
  o.switch_every = N;
  o.probe_every = 5;
  o.device = Device::Cuda;
  Model m;
  m.net = fresh("small");
  ContinuousResult r = train_continuous(m, {0, 1}, load, o);
  ASSERT_EQ(r.windows.size(), 2u);
  ASSERT_EQ(r.loss_history.size(), size_t(2 * N));
  EXPECT_GT(r.loss_history[N], 2.5f * r.loss_history[N - 1]);
  EXPECT_EQ(r.probes.size(), size_t(2 * (N / 5 + 1)));
  EXPECT_EQ(r.windows[1].first_step, N);
  EXPECT_GT(r.windows[1].psnr_end, r.windows[1].psnr_after + 3);
  std::printf("continuous on the GPU: PSNR after the switch %.2f, end %.2f dB\n", r.windows[1].psnr_after,
              r.windows[1].psnr_end);
}

// A multi-brick model on the GPU: decode (each brick's network on the GPU, blended on the host) within
// half precision of the CPU's; the render (from that decode, as a grid) against the CPU's direct render:
// trilinear between voxel centres instead of the networks, which shadow rays amplify (H100: 44.7 dB ray
// marching, 33.2 dB with shadows).
TEST(GpuBricks, DecodeAndRenderMatchTheCpu) {
  REQUIRE_GPU();
  TmpDir dir("gpu_bricks");
  synth_volume("marschner-lobb", Int3{48, 40, 32}, dir / "v.json");
  train_bricks(small_brick_setup(dir / "v.json"), Int3{2, 2, 1}, 2, dir / "m", brick_steps(150));
  const Model m = load_model(dir / "m");
  ASSERT_TRUE(m.bricks);
  ModelQuery cpu(m, Device::Cpu), gpu(m, Device::Cuda);
  const Volume dc = cpu.decode(), dg = gpu.decode();
  double worst = 0;
  for (size_t i = 0; i < dc.data.size(); ++i) worst = std::max(worst, double(std::fabs(dc.data[i] - dg.data[i])));
  std::printf("multi-brick decode, GPU vs CPU: max difference %.2e\n", worst);
  EXPECT_LT(worst, 2e-2);
  EXPECT_EQ(choose_render_device("auto", &m), Device::Cuda);
  for (auto [mode, bound] : {std::pair{RenderMode::RayMarch, 40.0}, std::pair{RenderMode::Shadow, 30.0}}) {
    Renderer rc(m, Device::Cpu), rg(m, Device::Cuda);
    for (Renderer* r : {&rc, &rg}) {
      r->set_mode(mode);
      r->set_size(96, 80);
      for (int i = 0; i < 4; ++i) r->render_frame();
    }
    const double p = image_psnr(rg.image(), rc.image());
    std::printf("multi-brick %s, GPU (decoded) vs CPU (networks): %.1f dB\n", render_mode_name(mode), p);
    EXPECT_GT(p, bound);
  }
  // From the brick cache: the GPU's copy, decoded brick by brick (no whole decode), against the CPU's.
  Renderer rc(m, Device::Cpu), rg(m, Device::Cuda);
  for (Renderer* r : {&rc, &rg}) {
    r->set_size(96, 80);
    r->choose_strategy("cache");
    r->warm_cache();
    for (int i = 0; i < 4; ++i) r->render_frame();
  }
  const double p = image_psnr(rg.image(), rc.image());
  std::printf("multi-brick raymarch from the brick cache, GPU copy vs CPU: %.1f dB (%lld bricks)\n", p,
              (long long)rg.cache_stats().resident);
  EXPECT_GT(p, 40.0);
  EXPECT_GT(rg.cache_stats().resident, 0);
}

// `vnr train --device cuda --target-ratio`: quantization-aware and rate-aware steps run on the GPU
// (GpuTrainer::begin_quantized) as on the CPU (the session's step hooks): the same file size, the
// quantized network within a dB of the CPU's after the same steps, and the rate term zeroing more of
// the quantized grid on both.
TEST(GpuCompact, QuantizedAndRateAwareStepsRunOnTheGpuAsOnTheCpu) {
  REQUIRE_GPU();
  TmpDir dir("gpu_qat");
  synth_volume("marschner-lobb", Int3{48, 48, 48}, dir / "v.json");
  struct Run {
    double psnr, zero_share;
    int64_t qat_steps, bytes;
  };
  auto run = [&](const char* device, double rate_weight) {
    TrainingSetup s;
    s.volume = dir / "v.json";
    s.config = "small";
    s.batch = 16384;
    s.seed = 4;
    s.device = device;
    s.target_ratio = 8;
    s.qat_fraction = 0.5;
    s.rate_weight = rate_weight;
    s.session.output = dir / fmt::format("{}_{}.vnr", device, rate_weight);
    auto session = open_training_session(s);
    const Json summary = train_compact(*session, 400, 0, session->options().compact);
    session->finish({.ssim = false});
    const Model m = load_model(s.session.output);
    const size_t first_grid = make_mlp_layout(m.net->config()).n_matrices;
    const std::vector<uint16_t> p = m.net->params_half();
    uint64_t off = 0, zeros = 0, n = 0;
    for (size_t k = 0; k < m.param_segments.size(); ++k) {
      const ParamSegment& seg = m.param_segments[k];
      if (k >= first_grid && seg.step > 0)
        for (uint64_t i = off; i < off + seg.count; ++i, ++n) zeros += half_to_float(p[i]) == 0.0f;
      off += seg.count;
    }
    return Run{summary["heldback_psnr"].get<double>(), double(zeros) / double(std::max<uint64_t>(n, 1)),
               summary["qat_steps"].get<int64_t>(), int64_t(std::filesystem::file_size(s.session.output))};
  };
  const Run gpu = run("cuda", 0), cpu = run("cpu", 0), gpu_rate = run("cuda", 3), cpu_rate = run("cpu", 3);
  std::printf("compact 8x, 200 QAT steps: held-back PSNR %.2f dB GPU, %.2f CPU; grid zeros %.3f / %.3f, with the "
              "rate term %.3f / %.3f\n", gpu.psnr, cpu.psnr, gpu.zero_share, cpu.zero_share, gpu_rate.zero_share,
              cpu_rate.zero_share);
  EXPECT_EQ(gpu.qat_steps, 200);
  EXPECT_EQ(gpu_rate.qat_steps, 200);
  EXPECT_NEAR(double(gpu.bytes), double(cpu.bytes), 0.05 * double(cpu.bytes));
  EXPECT_NEAR(gpu.psnr, cpu.psnr, 1.0);
  EXPECT_GT(gpu_rate.zero_share, gpu.zero_share + 0.05);
  EXPECT_NEAR(gpu_rate.zero_share, cpu_rate.zero_share, 0.1);
}
