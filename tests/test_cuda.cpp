// The CUDA backend's CPU-checkable parts (always run): device resolution without a GPU, the CLI's
// --device errors, and the per-sample form of the training sampler that the GPU kernels use, against
// the CPU's. The GPU kernels themselves are tested in test_gpu.cpp (ctest label `gpu`).
#include <gtest/gtest.h>
#include <hwy/targets.h>
#include <cmath>
#include <numeric>
#include "test_support.h"
#include "vnr/core/rng.h"
#include "vnr/cuda/cuda.h"
#include "vnr/fields/fields.h"
#include "vnr/render_cuda/gpu_renderer.h"
#include "vnr/nn/loss.h"
#include "vnr/nn/network.h"
#include "vnr/train/model_io.h"
#include "vnr/train/sampler.h"
#include "vnr/train/trainer.h"

using namespace vnr;

namespace {

// ---- CPU-checkable -------------------------------------------------------------------------------

// On every SIMD target (the AVX-512 one draws two sample slots of the four streams per vector).
TEST(CudaSampler, PerSampleCoordinatesEqualTheChunkSampler) {
  for (int64_t t : hwy::SupportedAndGeneratedTargets()) {
    hwy::SetSupportedTargetsForTest(t);
    SCOPED_TRACE(hwy::TargetName(t));
    for (int n : {256, 1024, 37, 44, 8, 7, 3}) {
      std::vector<float> x(n), y(n), z(n);
      uniform_coordinates(1337, 5, 11, n, x.data(), y.data(), z.data());
      for (int i = 0; i < n; ++i) {
        float px, py, pz;
        uniform_sample_coordinate(1337, 5, 11, n, i, &px, &py, &pz);
        ASSERT_EQ(px, x[i]) << "n " << n << " i " << i;
        ASSERT_EQ(py, y[i]);
        ASSERT_EQ(pz, z[i]);
      }
    }
  }
  hwy::SetSupportedTargetsForTest(0);
}

TEST(CudaDevice, AutoFallsBackToTheCpuAndCudaSaysWhyNot) {
  EXPECT_EQ(cuda::resolve_device("cpu"), Device::Cpu);
  test::expect_error([] { cuda::resolve_device("gpu"); }, {"unknown --device 'gpu'", "auto, cpu, cuda"});
  const int n = int(cuda::devices().size());
  if (n > 0) {
    EXPECT_EQ(cuda::resolve_device("auto"), Device::Cuda);
    EXPECT_EQ(cuda::use_device_for(n + 1), 1 % n) << "slots wrap around the devices";
    EXPECT_EQ(cuda::use_device_for(0), 0);
    return;
  }
  EXPECT_EQ(cuda::resolve_device("auto"), Device::Cpu);
  EXPECT_EQ(cuda::use_device_for(3), -1) << "no device: nothing to choose";
  const std::string msg = test::one_line_error_of([] { cuda::resolve_device("cuda"); });
  EXPECT_TRUE(msg.find("no CUDA device") != std::string::npos || msg.find("built without") != std::string::npos)
      << msg;
  EXPECT_FALSE(cuda::no_device_reason().empty());
}

TEST(CudaDevice, UnsupportedModelsGetOneClearLine) {
  Json cfg = test::mlp_model_config({{"otype", "Frequency"}, {"n_frequencies", 2}}, 16, 1);
  Network freq(cfg);
  test::expect_error([&] { cuda::check_supported(freq); }, {"grid encodings", "--device cpu"});
  Json linear = preset_config("tiny");
  linear["network"]["activation"] = "None";
  Network lin(linear);
  test::expect_error([&] { cuda::check_supported(lin); }, {"ReLU", "--device cpu"});
  Json odd = preset_config("tiny");  // 4 features a level, width 9: 16 x 9 + 9 x 9 + 8 x 9 = 297 MLP parameters
  odd["encoding"]["n_features_per_level"] = 4;
  odd["network"]["otype"] = "CutlassMLP";
  odd["network"]["n_neurons"] = 9;
  Network misaligned(odd);
  ASSERT_NE(misaligned.mlp().n_params % 4, 0u);
  test::expect_error([&] { cuda::check_supported(misaligned); }, {"multiple of the grid's 4 features", "--device cpu"});
  odd["network"]["n_neurons"] = 24;  // a CutlassMLP width GPU training runs
  EXPECT_NO_THROW(cuda::check_supported(Network(odd)));
  Network ok(preset_config("tiny"));
  EXPECT_NO_THROW(cuda::check_supported(ok));
  EXPECT_EQ(cuda::parse_mlp_path("fused"), cuda::MlpPath::Fused);
  test::expect_error([] { cuda::parse_mlp_path("cutlass"); }, {"unknown MLP path", "auto, fused, cublas"});
}

TEST(CudaCli, InfoAndVersionNameTheBackends) {
  test::Result info = test::run("info --json");
  ASSERT_EQ(info.code, 0) << info.err;
  Json j = Json::parse(info.out);
  EXPECT_EQ(j["cuda"]["built"].get<bool>(), cuda::built());
  EXPECT_EQ(j["cuda"]["devices"].size(), cuda::devices().size());
  EXPECT_EQ(j["default_device"], cuda::devices().empty() ? "cpu" : "cuda");
  test::Result v = test::run("--version");
  ASSERT_EQ(v.code, 0);
  EXPECT_HAS(v.out, "backends: cpu [");
  EXPECT_HAS(v.out, cuda::built() ? "cuda" : "cuda: not built");
}

TEST(CudaCli, DeviceCudaWithoutAGpuIsOneErrorLine) {
  if (!cuda::devices().empty()) GTEST_SKIP() << "a CUDA device is present";
  test::TmpDir dir;
  const std::string why = cuda::built() ? "no CUDA device" : "built without the CUDA backend";
  test::Result s = test::run("synth marschner-lobb --dims 16,16,16 -o " + dir / "v.json");
  ASSERT_EQ(s.code, 0) << s.err;
  test::expect_error("train " + dir / "v.json" + " -o " + dir / "m.vnr --config tiny --steps 2 --device cuda", why);
  test::expect_error("bench train " + dir / "v.json" + " --config tiny --seconds 0.1 --device cuda", why);
  test::expect_error("train " + dir / "v.json" + " -o " + dir / "m.vnr --config tiny --steps 2 --device tpu",
                     "--device");
  // auto trains on the CPU and records it
  test::Result t = test::run("train " + dir / "v.json" + " -o " + dir / "m.vnr --config tiny --steps 2 --report " +
                             dir / "r.json");
  ASSERT_EQ(t.code, 0) << t.err;
  EXPECT_EQ(Json::parse(read_file(dir / "r.json"))["device"], "cpu");
}

// GPU rendering without a GPU: render and bench render with --device cuda say why in one line; auto
// renders on the CPU and the report says so; the library's GpuRenderer fails the same way.
TEST(CudaCli, RenderOnCudaWithoutAGpuIsOneErrorLineAndAutoUsesTheCpu) {
  if (!cuda::devices().empty()) GTEST_SKIP() << "a CUDA device is present";
  test::TmpDir dir;
  const std::string why = cuda::built() ? "no CUDA device" : "built without the CUDA backend";
  ASSERT_EQ(test::run("synth marschner-lobb --dims 16,16,16 -o " + dir / "v.json").code, 0);
  test::expect_error("render " + dir / "v.json" + " -o " + dir / "a.png --size 8x8 --device cuda", why);
  test::expect_error("bench render " + dir / "v.json" + " --size 8x8 --frames 1 --device cuda", why);
  test::expect_error("render " + dir / "v.json" + " -o " + dir / "a.png --mlp tensor", "--mlp");
  test::Result r = test::run("render " + dir / "v.json" + " -o " + dir / "a.png --size 8x8 --report " + dir / "r.json");
  ASSERT_EQ(r.code, 0) << r.err;
  const Json rep = Json::parse(read_file(dir / "r.json"));
  EXPECT_EQ(rep["device"], "cpu");
  EXPECT_EQ(rep["host_syncs"], 0);
  Volume vol = test::synth(Int3{8, 8, 8});
  GridField field(view_of(vol));
  MacroCells mc = MacroCells::single(vol.dims, test::box_of(vol));
  test::expect_error([&] { GpuRenderer(field.gpu_source(), test::box_of(vol), mc, tf_preset("ramp"), Camera{}, RenderOptions{}); },
                     {why.c_str()});
}

}  // namespace
