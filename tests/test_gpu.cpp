// The CUDA backend's kernels against the CPU reference (ctest label `gpu`). Without a CUDA device (CI
// has the toolkit but no GPU) every test reports itself skipped with the reason.
#include <gtest/gtest.h>
#include <cmath>
#include <numeric>
#include "test_support.h"
#include "vnr/core/rng.h"
#include "vnr/cuda/cuda.h"
#include "vnr/nn/loss.h"
#include "vnr/nn/network.h"
#include "vnr/train/model_io.h"
#include "vnr/train/sampler.h"
#include "vnr/train/trainer.h"

using namespace vnr;
using vnr::test::max_abs_diff;

namespace {

#define REQUIRE_GPU()                                                                      \
  do {                                                                                     \
    if (cuda::devices().empty()) GTEST_SKIP() << "no CUDA device: " << cuda::no_device_reason(); \
  } while (0)

// ---- GPU (label gpu) -----------------------------------------------------------------------------

std::vector<float> random_points(int n, uint64_t seed) {
  Pcg32 rng(seed);
  std::vector<float> p(size_t(3 * n));
  for (float& v : p) v = rng.next_float();
  return p;
}

// A small model trained a few CPU steps on a smooth volume, so outputs and gradients are not tiny
// (with `loss`, that loss instead of the preset's).
std::unique_ptr<Network> trained_network(const std::string& preset, const Volume& vol, int steps = 30,
                                         const char* loss = nullptr) {
  Json cfg = preset_config(preset);
  if (loss) cfg["loss"] = {{"otype", loss}};
  auto net = std::make_unique<Network>(cfg);
  net->init_params(7);
  CpuTrainer tr(*net, std::make_shared<InCoreSampler>(vol), TrainOptions{4096, 7});
  for (int i = 0; i < steps; ++i) tr.step();
  return net;
}

double relative_l2(const float* a, const float* b, size_t n) {
  double num = 0, den = 0;
  for (size_t i = 0; i < n; ++i) {
    num += double(a[i] - b[i]) * double(a[i] - b[i]);
    den += double(b[i]) * double(b[i]);
  }
  return std::sqrt(num / std::max(den, 1e-30));
}

TEST(GpuEncoding, EqualsTheCpuEncodingRoundedToHalf) {
  REQUIRE_GPU();
  std::vector<std::pair<std::string, Json>> configs = {{"paper", preset_config("paper")}, {"small", preset_config("small")}};
  for (int f : {1, 4}) {  // the feature counts no preset uses, each with its own GPU kernels
    Json c = preset_config("small");
    c["encoding"]["n_features_per_level"] = f;
    configs.emplace_back("small, " + std::to_string(f) + " features", c);
  }
  for (const auto& [preset, config] : configs) {
    Network net(config);
    net.init_params(3);
    net.edit_params([&](float* p, size_t) {
      float* table = p + net.mlp().n_params;
      for (uint64_t i = 0; i < net.grid_params(); ++i) table[i] = float(int(i % 97) - 48) * 1e-2f;
    });
    const int n = 256;
    std::vector<float> pts = random_points(n, 1);
    pts[0] = 0.0f;  // domain corners: the +0.5 offset and the wrap of dense levels (docs/semantics.md A.2.5)
    pts[1] = 1.0f;
    pts[2] = 0.999999f;
    std::vector<float> gpu = cuda::testing::encode(net, pts.data(), n);
    const uint32_t in_pad = net.mlp().in_pad;
    std::vector<float> x(n), y(n), z(n), X0(size_t(in_pad) * n);
    for (int i = 0; i < n; ++i) x[i] = pts[3 * i], y[i] = pts[3 * i + 1], z[i] = pts[3 * i + 2];
    net.encode(x.data(), y.data(), z.data(), n, X0.data());
    for (int i = 0; i < n; ++i)
      for (uint32_t c = 0; c < in_pad; ++c)
        ASSERT_EQ(gpu[size_t(i) * in_pad + c], half_to_float(float_to_half(X0[size_t(c) * n + i])))
            << preset << " point " << i << " feature " << c;
  }
}

// Half weights and activations (tcnn's precision) against the CPU's binary32 MLP: each of the ~5
// roundings to half adds up to 2^-11 relative, so outputs agree to ~1e-2 of their scale; fused and
// cuBLAS paths share the roundings and differ only in accumulation order.
TEST(GpuMlp, InferenceMatchesTheCpuWithinHalfPrecision) {
  REQUIRE_GPU();
  const Volume vol = test::synth(Int3{32, 32, 32});
  for (const char* preset : {"paper", "small"}) {
    auto net = trained_network(preset, vol);
    const int n = 4099;  // not a multiple of 16: the padded tail
    std::vector<float> pts = random_points(n, 2), cpu(n), fused(n), blas(n);
    net->infer(pts.data(), n, cpu.data());
    cuda::GpuNetwork gf(*net, cuda::MlpPath::Fused);
    gf.set_slab(1000);  // several slabs
    gf.infer(pts.data(), n, fused.data());
    cuda::GpuNetwork gb(*net, cuda::MlpPath::Cublas);
    gb.infer(pts.data(), n, blas.data());
    double scale = 0;
    for (float v : cpu) scale = std::max(scale, double(std::fabs(v)));
    EXPECT_LT(max_abs_diff(fused, cpu), 2e-2 * std::max(scale, 0.1)) << preset;
    EXPECT_LT(max_abs_diff(blas, cpu), 2e-2 * std::max(scale, 0.1)) << preset;
    EXPECT_LT(max_abs_diff(fused, blas), 2e-3 * std::max(scale, 0.1)) << preset;
    // decode_slices on the GPU is infer() at the voxel centres
    Int3 dims{9, 7, 5};
    std::vector<float> dec(dims.count()), centres(3 * dims.count()), ref(dims.count());
    for (int64_t v = 0; v < int64_t(dims.count()); ++v)
      voxel_centre(dims, v, &centres[3 * v], &centres[3 * v + 1], &centres[3 * v + 2]);
    gf.decode_slices(dims, 0, 5, dec.data());
    gf.infer(centres.data(), int64_t(dims.count()), ref.data());
    EXPECT_EQ(dec, ref) << preset;
  }
}

// The CPU gradient of the same batch from the Network's chunk kernels (binary32 MLP).
std::vector<float> cpu_gradient(const Network& net, const std::vector<float>& pts, const std::vector<float>& tgt,
                                int n, float* loss) {
  const MlpLayout& m = net.mlp();
  std::vector<float> x(n), y(n), z(n), X0(size_t(m.in_pad) * n), acts(net.acts_floats(n)), pre(n), out(n), dout(n),
      dX0(size_t(m.in_pad) * n), scratch(size_t(2) * m.width * n), grad(net.n_params(), 0.0f);
  for (int i = 0; i < n; ++i) x[i] = pts[3 * i], y[i] = pts[3 * i + 1], z[i] = pts[3 * i + 2];
  net.encode(x.data(), y.data(), z.data(), n, X0.data());
  net.mlp_forward(X0.data(), n, acts.data(), pre.data(), out.data());
  double l = 0;
  for (int i = 0; i < n; ++i) {
    float g;
    l += loss_value_and_grad(net.config().loss, out[i], tgt[i], 1.0f / float(n), &g);
    dout[i] = g * activate_derivative(m.output_activation, pre[i]);
  }
  *loss = float(l);
  net.mlp_backward(X0.data(), acts.data(), dout.data(), n, grad.data(), dX0.data(), scratch.data());
  for (uint32_t lv = 0; lv < net.grid().n_levels; ++lv)
    net.grid_backward_level(lv, x.data(), y.data(), z.data(), n, dX0.data(), n, grad.data() + m.n_params);
  return grad;
}

TEST(GpuGradient, MatchesTheCpuPerMatrixAndForTheGrid) {
  REQUIRE_GPU();
  const Volume vol = test::synth(Int3{32, 32, 32});
  for (const char* preset : {"paper", "small"}) {
    auto net = trained_network(preset, vol);
    Json cfg = net->config_json();
    const int n = 256;
    std::vector<float> pts = random_points(n, 3), tgt(n);
    for (int i = 0; i < n; ++i) tgt[i] = grid_lookup(view_of(vol), pts[3 * i], pts[3 * i + 1], pts[3 * i + 2]);
    float lc = 0, lf = 0, lb = 0;
    std::vector<float> cpu = cpu_gradient(*net, pts, tgt, n, &lc);
    std::vector<float> fused = cuda::testing::gradient(*net, pts.data(), tgt.data(), n, cuda::MlpPath::Fused, &lf);
    std::vector<float> blas = cuda::testing::gradient(*net, pts.data(), tgt.data(), n, cuda::MlpPath::Cublas, &lb);
    EXPECT_NEAR(lf, lc, 2e-2 * lc) << preset;
    EXPECT_NEAR(lb, lf, 1e-3 * lf) << preset;
    const MlpLayout& m = net->mlp();
    // Relative L2 error per block. L1 loss gradients are signs: a prediction within half precision of
    // its target may flip one, so the GPU/CPU bound is 10% (a transposed or misindexed kernel gives
    // ~100%); fused and cuBLAS share every rounding to half and differ in summation order only.
    for (uint32_t k = 0; k < m.n_matrices; ++k) {
      const size_t off = m.offset[k], cnt = m.rows[k] * m.cols[k];
      EXPECT_LT(relative_l2(fused.data() + off, cpu.data() + off, cnt), 0.1) << preset << " matrix " << k;
      EXPECT_LT(relative_l2(fused.data() + off, blas.data() + off, cnt), 0.01) << preset << " matrix " << k;
    }
    const size_t g0 = m.n_params, gn = net->grid_params();
    EXPECT_LT(relative_l2(fused.data() + g0, cpu.data() + g0, gn), 0.1) << preset << " grid";
    EXPECT_LT(relative_l2(fused.data() + g0, blas.data() + g0, gn), 0.01) << preset << " grid";
  }
}

// Level by level (the grid backward's blocks take the levels in turn; 1040 samples are four blocks of
// 256 and a tail per level): a level's gradients missing or landing in another level's entries give a
// relative error of 1 or more. Under the L2 loss a GPU/CPU difference of the output changes a sample's
// gradient by as much, not by its whole size as a sign flip of the L1 loss's may; hence the tighter bound.
TEST(GpuGradient, EveryGridLevelMatchesTheCpuUnderTheL2Loss) {
  REQUIRE_GPU();
  const Volume vol = test::synth(Int3{32, 32, 32});
  for (const char* preset : {"paper", "small"}) {
    auto net = trained_network(preset, vol, 30, "L2");
    const int n = 1040;
    std::vector<float> pts = random_points(n, 5), tgt(n);
    for (int i = 0; i < n; ++i) tgt[i] = grid_lookup(view_of(vol), pts[3 * i], pts[3 * i + 1], pts[3 * i + 2]);
    float lc = 0, lf = 0;
    std::vector<float> cpu = cpu_gradient(*net, pts, tgt, n, &lc);
    std::vector<float> gpu = cuda::testing::gradient(*net, pts.data(), tgt.data(), n, cuda::MlpPath::Fused, &lf);
    const GridLayout& grid = net->grid();
    double worst = 0;
    uint32_t worst_level = 0;
    for (uint32_t l = 0; l < grid.n_levels; ++l) {
      const size_t lo = net->mlp().n_params + size_t(grid.levels[l].offset) * grid.n_features;
      const size_t cnt = size_t(grid.levels[l].n_entries) * grid.n_features;
      const double err = relative_l2(gpu.data() + lo, cpu.data() + lo, cnt);
      EXPECT_LT(err, 0.1) << preset << " grid level " << l;
      if (err > worst) worst = err, worst_level = l;
    }
    std::printf("%s: GPU vs CPU grid gradients level by level, relative L2 at most %.2e (level %u)\n", preset, worst,
                worst_level);
  }
}

TEST(GpuTrainer, LossCurveAndPsnrFollowTheCpuAndModelsMoveBothWays) {
  REQUIRE_GPU();
  const Volume vol = test::synth(Int3{48, 48, 48});
  const int steps = 500;
  auto make = [] {
    auto net = std::make_unique<Network>(preset_config("small"));
    net->init_params(11);
    return net;
  };
  auto cpu_net = make();
  CpuTrainer cpu(*cpu_net, std::make_shared<InCoreSampler>(vol), TrainOptions{16384, 5});
  for (int i = 0; i < steps; ++i) cpu.step();
  auto gpu_net = make();
  cuda::GpuTrainer gpu(*gpu_net, view_of(vol),
                       cuda::GpuTrainOptions{16384, 5, kChunk, cuda::MlpPath::Auto});
  // One step first: the Adam update of the first step is lr * sign(g) for every touched parameter, so
  // parameters move by the learning rate in the same direction wherever the gradients agree in sign.
  {
    auto one_cpu = make();
    CpuTrainer c1(*one_cpu, std::make_shared<InCoreSampler>(vol), TrainOptions{16384, 5});
    c1.step();
    auto one_gpu = make();
    cuda::GpuTrainer g1(*one_gpu, view_of(vol), cuda::GpuTrainOptions{16384, 5, kChunk});
    g1.run(1);
    g1.download();
    size_t agree = 0;
    const auto &cpu = one_cpu->params(), &gpu = one_gpu->params();
    for (size_t i = 0; i < cpu.size(); ++i) agree += std::fabs(cpu[i] - gpu[i]) <= 1e-6f + 1e-3f * std::fabs(cpu[i]);
    EXPECT_GT(double(agree) / double(cpu.size()), 0.95);
  }
  gpu.run(steps);
  std::vector<float> lg = gpu.losses();
  ASSERT_EQ(lg.size(), size_t(steps));
  EXPECT_EQ(gpu.losses(steps - 3), std::vector<float>(lg.end() - 3, lg.end())) << "a poller's new losses";
  EXPECT_TRUE(gpu.losses(steps + 5).empty());
  gpu.download();
  const std::vector<float>& lc = cpu.loss_history();
  auto tail_mean = [](const std::vector<float>& l) { return std::accumulate(l.end() - 50, l.end(), 0.0) / 50; };
  EXPECT_NEAR(tail_mean(lg), tail_mean(lc), 0.1 * tail_mean(lc));
  EXPECT_LT(lg.back(), 0.3f * lg.front());
  const double p_cpu = evaluate(*cpu_net, vol, false).psnr;
  const double p_gpu_on_cpu = evaluate(*gpu_net, vol, false, Device::Cpu).psnr;
  const double p_gpu_on_gpu = evaluate(*gpu_net, vol, false, Device::Cuda).psnr;
  const double p_cpu_on_gpu = evaluate(*cpu_net, vol, false, Device::Cuda).psnr;
  EXPECT_NEAR(p_gpu_on_cpu, p_cpu, 0.3);
  EXPECT_NEAR(p_gpu_on_gpu, p_gpu_on_cpu, 0.3);
  EXPECT_NEAR(p_cpu_on_gpu, p_cpu, 0.3);
  // Through a model file: trained on the GPU, read back and evaluated on the CPU.
  test::TmpDir dir;
  Model m;
  m.net = std::move(gpu_net);
  m.dims = vol.dims;
  save_model(dir / "g.vnr", m);
  Model back = load_model(dir / "g.vnr");
  EXPECT_NEAR(evaluate(*back.net, vol, false, Device::Cpu).psnr, p_gpu_on_cpu, 0.05);
}

}  // namespace
