// GPU rendering against the CPU renderer (ctest label `gpu`): macro-cell ranges and opacities computed on
// the GPU equal the CPU's exactly; the online ranges of the GPU trainer equal the CPU trainer's; images of
// the grid and of a trained network match the CPU's for every integrator and both strategies; streaming
// and in-shader agree on the GPU; macro-cells on and off agree; the GPU's copy of the brick cache matches
// the CPU's cache; renderers and decoders refreshed in place with a trainer's device parameters equal new
// ones. Without a CUDA device every test reports itself skipped with the reason.
#include <gtest/gtest.h>
#include <algorithm>
#include <cmath>
#include "render_support.h"
#include "test_support.h"
#include "vnr/api/model_field.h"
#include "vnr/core/value_range_grid.h"
#include "vnr/cuda/cuda.h"
#include "vnr/render/renderer.h"
#include "vnr/render_cuda/gpu_renderer.h"
#include "vnr/renderer.h"
#include "vnr/train/sampler.h"
#include "vnr/train/trainer.h"

using namespace vnr;
using namespace vnr::test;

namespace {

#define REQUIRE_GPU()                                                                              \
  do {                                                                                             \
    if (cuda::devices().empty()) GTEST_SKIP() << "no CUDA device: " << cuda::no_device_reason(); \
  } while (0)

double image_psnr(const Image& a, const Image& b) { return compare_images(a, b).psnr; }

// Paired test of two Monte Carlo images: the mean per-pixel difference of r+g+b is within 4 standard
// errors of zero (plus a float-noise floor).
void expect_equal_means(const Image& a, const Image& b, const std::string& what) {
  const size_t n = a.pixels.size();
  double sum = 0, sum2 = 0, mean_a = 0;
  for (size_t i = 0; i < n; ++i) {
    const Vec4f &p = a.pixels[i], &q = b.pixels[i];
    const double d = double(p.x + p.y + p.z) - double(q.x + q.y + q.z);
    sum += d;
    sum2 += d * d;
    mean_a += double(p.x + p.y + p.z);
  }
  const double mean = sum / double(n), var = std::max(0.0, sum2 / double(n) - mean * mean);
  const double se = std::sqrt(var / double(n));
  EXPECT_LT(std::fabs(mean), 4 * se + 1e-4) << what << ": mean difference " << mean << ", standard error " << se;
  EXPECT_GT(mean_a / double(n), 1e-3) << what << ": the image is not empty";
}

// A GPU trainer of net (the small config, initialised with seed 3) on vol.
std::unique_ptr<cuda::GpuTrainer> gpu_trainer_of(Network& net, const Volume& vol) {
  net.init_params(3);
  return std::make_unique<cuda::GpuTrainer>(net, view_of(vol),
                                            cuda::GpuTrainOptions{16384, 3, kChunk, cuda::MlpPath::Auto});
}

std::unique_ptr<FrameRenderer> renderer_on(Device dev, const RenderableField& f, const Volume& vol, const MacroCells& mc,
                                           const TransferFunction& tf, const Camera& cam, const RenderOptions& o) {
  return make_renderer(dev, f, box_of(vol), mc, tf, cam, o);
}

TEST(GpuMacroCells, RangesAndOpacitiesEqualTheCpuExactly) {
  REQUIRE_GPU();
  Volume vol = blobs(Int3{50, 44, 40});
  for (int cs : {8, 16}) {
    const ValueRangeGrid cpu = value_ranges_from_grid(view_of(vol), cs);
    const ValueRangeGrid gpu = gpu_value_ranges_from_grid(view_of(vol), cs);
    ASSERT_EQ(gpu.cells, cpu.cells);
    for (int64_t c = 0; c < cpu.count(); ++c) {
      ASSERT_EQ(gpu.lo[c], cpu.lo[c]) << "cell " << c;
      ASSERT_EQ(gpu.hi[c], cpu.hi[c]) << "cell " << c;
    }
  }
  GridField field(view_of(vol));
  MacroCells mc(value_ranges_from_grid(view_of(vol), 8), box_of(vol));
  RenderOptions o;
  o.width = o.height = 16;
  Camera cam = orbit_camera(box_of(vol), 10, 10, 30);
  TransferFunction ramp = tf_preset("ramp");
  GpuRenderer r(field.gpu_source(), box_of(vol), mc, ramp, cam, o);
  // the opacities follow the transfer function and the ranges, recomputed on the GPU each time
  for (const std::string& name : tf_preset_names()) {
    TransferFunction tf = tf_preset(name);
    r.set_transfer_function(tf);
    mc.update(tf);
    EXPECT_EQ(r.max_opacity(), mc.max_opacity()) << name;
  }
  MacroCells coarse(value_ranges_from_grid(view_of(vol), 16), box_of(vol));
  coarse.update(tf_preset(tf_preset_names().back()));
  r.set_ranges(coarse.ranges());
  EXPECT_EQ(r.max_opacity(), coarse.max_opacity());
}

TEST(GpuMacroCells, OnlineRangesOfTheGpuTrainerEqualTheCpuTrainers) {
  REQUIRE_GPU();
  Volume vol = blobs(Int3{40, 36, 32});
  Network cpu_net(preset_config("tiny")), gpu_net(preset_config("tiny"));
  cpu_net.init_params(5);
  gpu_net.init_params(5);
  const int64_t batch = 4096;
  CpuTrainer cpu(cpu_net, std::make_shared<InCoreSampler>(vol), TrainOptions{batch, 9});
  cpu.enable_online_ranges(vol.dims, 8);
  cuda::GpuTrainer gpu(gpu_net, view_of(vol), cuda::GpuTrainOptions{batch, 9, kChunk});
  gpu.enable_online_ranges(vol.dims, 8);
  for (int i = 0; i < 3; ++i) cpu.step();
  gpu.run(3);
  const ValueRangeGrid a = cpu.online_ranges(), b = gpu.online_ranges();
  ASSERT_EQ(a.cells, b.cells);
  int64_t touched = 0;
  for (int64_t c = 0; c < a.count(); ++c) {
    ASSERT_EQ(b.lo[c], a.lo[c]) << "cell " << c;
    ASSERT_EQ(b.hi[c], a.hi[c]) << "cell " << c;
    touched += !a.empty(c);
  }
  EXPECT_GT(touched, a.count() / 2);
}

// Grid images: the GPU runs the CPU's per-ray functions on the same values (grid_lookup, built without
// FMA contraction on both; a step's opacity is unit_pow's plain arithmetic, no libm), so ray marching and
// shadows agree to float noise (the shading's sqrtf and powf may differ by an ulp between libm and CUDA);
// path tracing takes the same random decisions almost everywhere, so its mean is tested.
TEST(GpuRender, GridImagesMatchTheCpu) {
  REQUIRE_GPU();
  const GridScene scene;
  for (RenderMode mode : {RenderMode::RayMarch, RenderMode::Shadow, RenderMode::PathTrace})
    for (bool shade : {false, true}) {
      if (shade && mode != RenderMode::RayMarch) continue;
      for (RenderStrategy strategy : {RenderStrategy::Streaming, RenderStrategy::InShader}) {
        RenderOptions o;
        o.mode = mode;
        o.shade = shade;
        o.strategy = strategy;
        o.width = 61;  // not a multiple of the GPU's 16 x 8 pixel blocks
        o.height = 45;
        o.seed = 5;
        o.samples_per_iteration = 3;
        const std::string what = std::string(render_mode_name(mode)) + (shade ? " shaded " : " ") +
                                 render_strategy_name(strategy);
        RenderStats cs, gs;
        auto render_on = [&](Device dev, RenderStats* st) {
          return renderer_on(dev, scene.field, scene.vol, scene.mc, scene.tf, scene.cam, o)->render(4, st);
        };
        const Image cpu = render_on(Device::Cpu, &cs);
        const Image gpu = render_on(Device::Cuda, &gs);
        ASSERT_EQ(gpu.width, cpu.width);
        ASSERT_EQ(gpu.height, cpu.height);
        if (mode == RenderMode::PathTrace) {
          expect_equal_means(gpu, cpu, what);
        } else {
          EXPECT_GT(image_psnr(gpu, cpu), 60.0) << what;
          EXPECT_NEAR(double(gs.field_samples), double(cs.field_samples), 1e-3 * double(cs.field_samples)) << what;
        }
        if (strategy == RenderStrategy::Streaming)
          EXPECT_EQ(gs.host_syncs, gs.iterations + gs.frames * (mode == RenderMode::Shadow ? 3 : 2))
              << what << ": one host synchronisation per iteration, one per pass that finds no live ray left, "
              << "one at the frame's end";
      }
    }
}

// What a viewer shows: the mean of frames 0..f as 8-bit RGBA, kept on the GPU, equals the host's
// accumulation of the same renderer's frames (FrameRenderer's own render_mean_rgba8) byte for byte, and
// the CPU renderer's within the images' agreement.
TEST(GpuRender, MeanOfFramesAsRgba8EqualsTheHostsAccumulation) {
  REQUIRE_GPU();
  const GridScene scene;
  for (RenderMode mode : {RenderMode::RayMarch, RenderMode::PathTrace}) {
    RenderOptions o;
    o.mode = mode;
    o.strategy = RenderStrategy::InShader;
    o.width = 61;
    o.height = 45;
    auto gpu = renderer_on(Device::Cuda, scene.field, scene.vol, scene.mc, scene.tf, scene.cam, o);
    auto host = renderer_on(Device::Cuda, scene.field, scene.vol, scene.mc, scene.tf, scene.cam, o);
    auto cpu = renderer_on(Device::Cpu, scene.field, scene.vol, scene.mc, scene.tf, scene.cam, o);
    std::vector<uint8_t> on_gpu, on_host, of_cpu;
    for (uint32_t f = 0; f < 5; ++f) {
      gpu->render_mean_rgba8(f, on_gpu);
      host->FrameRenderer::render_mean_rgba8(f, on_host);
      cpu->render_mean_rgba8(f, of_cpu);
      ASSERT_EQ(on_gpu.size(), size_t(4 * 61 * 45));
      EXPECT_EQ(on_gpu, on_host) << render_mode_name(mode) << ", frame " << f;
    }
    // Over the black background every colour byte of an empty image is 0 (3 of 4 bytes).
    EXPECT_LT(std::count(on_gpu.begin(), on_gpu.end(), uint8_t(0)), int64_t(on_gpu.size() * 3 / 4)) << "not empty";
    if (mode == RenderMode::RayMarch) EXPECT_GT(rgba8_psnr(on_gpu, of_cpu), 45.0);
  }
}

// A trained network: the GPU's half-precision MLP (tensor cores) against the CPU's binary32 inference.
// Outputs differ by ~1e-3 of the value range, which moves opacities by less than that; images agree
// above 40 dB (a 1% error of every pixel would be 40 dB).
TEST(GpuRender, NetworkImagesMatchTheCpuAndStrategiesAgree) {
  REQUIRE_GPU();
  Volume vol = blobs(Int3{32, 32, 32});
  // small: width 16, one 16-column tile per layer; paper: width 64, 64 encoding columns (4 x 4 tiles);
  // small with 4 features a level: the in-shader kernels of a feature count no preset uses
  Json small4 = preset_config("small");
  small4["encoding"]["n_features_per_level"] = 4;
  for (const auto& [preset, config] : {std::pair<std::string, Json>{"small", preset_config("small")},
                                       {"paper", preset_config("paper")}, {"small, 4 features", small4}}) {
  Network net(config);
  net.init_params(3);
  CpuTrainer trainer(net, std::make_shared<InCoreSampler>(vol), TrainOptions{16384, 3});
  trainer.enable_online_ranges(vol.dims, 8);
  for (int i = 0; i < 200; ++i) trainer.step();
  NetworkField neural(net, vol.dims);
  TransferFunction tf = tf_preset("ramp");
  MacroCells mc(trainer.online_ranges(), box_of(vol));
  mc.update(tf);
  Camera cam = orbit_camera(box_of(vol), 40, 25, 30);
  // ray marching also shaded: 7 field points a sample (the gradient's), kernels no other case launches
  for (const auto& [mode, shade] : {std::pair{RenderMode::RayMarch, false}, {RenderMode::Shadow, false},
                                    {RenderMode::PathTrace, false}, {RenderMode::RayMarch, true}}) {
    RenderOptions o;
    o.mode = mode;
    o.shade = shade;
    o.width = 64;
    o.height = 48;
    o.seed = 2;
    const std::string what = preset + " " + render_mode_name(mode) + (shade ? " shaded" : "");
    const Image cpu = renderer_on(Device::Cpu, neural, vol, mc, tf, cam, o)->render(4);
    const Image gpu_stream = renderer_on(Device::Cuda, neural, vol, mc, tf, cam, o)->render(4);
    {  // inference in slabs of 256 points: the same values (the fused MLP works per 16-sample tile)
      GpuRenderer slabbed(neural.gpu_source(), box_of(vol), mc, tf, cam, o);
      slabbed.set_inference_slab(256);
      const Image img = slabbed.render(4);
      for (size_t i = 0; i < img.pixels.size(); ++i)
        ASSERT_TRUE(img.pixels[i].x == gpu_stream.pixels[i].x && img.pixels[i].w == gpu_stream.pixels[i].w)
            << what << " pixel " << i;
    }
    o.strategy = RenderStrategy::InShader;
    const Image gpu_inshader = renderer_on(Device::Cuda, neural, vol, mc, tf, cam, o)->render(4);
    if (mode == RenderMode::PathTrace) {
      expect_equal_means(gpu_stream, cpu, what + " streaming");
      expect_equal_means(gpu_inshader, cpu, what + " in-shader");
    } else {
      const double ps = image_psnr(gpu_stream, cpu), pi = image_psnr(gpu_inshader, cpu);
      std::printf("%s: GPU vs CPU image PSNR %.1f dB (streaming), %.1f dB (in-shader); in-shader vs streaming %.1f dB\n",
                  what.c_str(), ps, pi, image_psnr(gpu_inshader, gpu_stream));
      // shaded: the gradient's central differences of half-precision values (a step of a voxel) add error
      const double floor = shade ? 30.0 : 40.0;
      EXPECT_GT(ps, floor) << what;
      EXPECT_GT(pi, floor) << what;
      EXPECT_GT(image_psnr(gpu_inshader, gpu_stream), floor + 5) << what << ": the same half-precision arithmetic";
    }
  }
  }
}

TEST(GpuRender, MacroCellsOnAndOffGiveTheSameRayMarchedImage) {
  REQUIRE_GPU();
  Volume vol = blobs(Int3{48, 48, 48});
  GridField field(view_of(vol));
  TransferFunction tf = tf_preset("ramp");
  Camera cam = orbit_camera(box_of(vol), 20, 15, 30);
  for (RenderStrategy strategy : {RenderStrategy::Streaming, RenderStrategy::InShader}) {
    auto render = [&](bool cells, RenderStats* st) {
      MacroCells mc = cells ? MacroCells(gpu_value_ranges_from_grid(view_of(vol), 8), box_of(vol))
                            : MacroCells::single(vol.dims, box_of(vol));
      mc.update(tf);
      RenderOptions o;
      o.width = o.height = 64;
      o.step_max = 1;  // uniform steps: only the placement of steps at cell boundaries differs
      o.strategy = strategy;
      return GpuRenderer(field.gpu_source(), box_of(vol), mc, tf, cam, o).render(4, st);
    };
    RenderStats on, off;
    EXPECT_GT(image_psnr(render(true, &on), render(false, &off)), 40.0) << render_strategy_name(strategy);
    EXPECT_LT(on.field_samples, off.field_samples) << "transparent cells are skipped";
  }
}

// A CutlassMLP's input is padded to 8 (here 4 levels of 2 features): the in-shader MLP's 16-wide tiles
// cannot run it (they used to, and computed a wrong first layer), so in-shader refuses it with the way
// out, `auto` streams, and streaming matches the CPU.
TEST(GpuRender, InShaderRefusesANetworkItsTilesCannotRunAndAutoStreams) {
  REQUIRE_GPU();
  Volume vol = blobs(Int3{32, 32, 32});
  Json cfg = preset_config("small");
  cfg["network"]["otype"] = "CutlassMLP";
  Model model = create_model(ModelConfig::from_json(cfg), vol);
  ASSERT_EQ(model.net->mlp().in_pad, 8u);
  CpuTrainer trainer(*model.net, std::make_shared<InCoreSampler>(vol), TrainOptions{16384, 3});
  for (int i = 0; i < 100; ++i) trainer.step();
  NetworkField neural(*model.net, vol.dims);
  TransferFunction tf = tf_preset("ramp");
  MacroCells mc = MacroCells::single(vol.dims, box_of(vol));
  mc.update(tf);
  Camera cam = orbit_camera(box_of(vol), 40, 25, 30);
  RenderOptions o;
  o.width = 64;
  o.height = 48;
  o.strategy = RenderStrategy::InShader;
  try {
    GpuRenderer refused(neural.gpu_source(), box_of(vol), mc, tf, cam, o);
    ADD_FAILURE() << "in-shader rendering took a network of 8-wide input tiles";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("--strategy streaming"), std::string::npos) << e.what();
  }
  const Renderer gpu_renderer(model, Device::Cuda);
  EXPECT_FALSE(gpu_renderer.can_render_inshader());
  EXPECT_EQ(gpu_renderer.automatic_strategy(), RenderStrategy::Streaming);
  o.strategy = RenderStrategy::Streaming;
  const Image gpu = renderer_on(Device::Cuda, neural, vol, mc, tf, cam, o)->render(4);
  const Image cpu = renderer_on(Device::Cpu, neural, vol, mc, tf, cam, o)->render(4);
  EXPECT_GT(image_psnr(gpu, cpu), 40.0);
  double mean = 0;  // and not two empty images
  for (const Vec4f& px : cpu.pixels) mean += double(px.w);
  EXPECT_GT(mean / double(cpu.pixels.size()), 1e-3);
}

}  // namespace

// The GPU renders from its copy of the brick cache (render_cuda/cache_copy.cuh), each sample at its own
// level of detail. Its image matches the CPU's warm cache (both read level 0 here; the GPU decodes in half
// precision) and the GPU's own network; the same host cache drawn by the GPU and by the CPU renderer reads
// the same voxels (the images differ only by the lookups' float rounding); a budget of a few bricks evicts
// and the image keeps no holes (coarser levels cover); `auto` takes the cache for accumulated frames.
TEST(GpuRender, BrickCacheCopyOnTheDeviceMatchesTheCpu) {
  REQUIRE_GPU();
  Volume vol = blobs(Int3{32, 32, 32});
  Model model = create_model(ModelConfig::from_json(preset_config("small")), vol);
  CpuTrainer trainer(*model.net, std::make_shared<InCoreSampler>(vol), TrainOptions{16384, 3});
  for (int i = 0; i < 200; ++i) trainer.step();
  const Camera cam = orbit_camera(box_of(vol), 40, 25, 30);
  auto image = [&](Device device, const char* strategy, uint64_t budget, Int3 dims, int width = 64) {
    Renderer r(model, device);
    r.set_size(width, width * 3 / 4);
    r.set_camera(cam);
    r.set_macrocells(MacroCellMode::Off);
    r.choose_strategy(strategy, budget, dims);
    if (budget) {  // close-ups of two columns of level-0 bricks: the second evicts the first's
      for (const Vec3f at : {Vec3f{4, 4, 0}, Vec3f{28, 28, 0}}) {
        r.set_camera(Camera{Vec3f{at.x, at.y, 42}, at, Vec3f{0, 1, 0}, 6});
        r.warm_cache();
        r.render_frame();
      }
      r.set_camera(cam);
    }
    r.warm_cache();
    for (int f = 0; f < 4; ++f) r.render_frame();
    EXPECT_STREQ(r.field().kind(), std::string(strategy) == "cache" ? "cache" : "network");
    if (budget) {
      EXPECT_GT(r.cache_stats().evicted, 0);
      EXPECT_LE(r.cache_stats().pool_bytes, budget);
    }
    return r.image();
  };
  const Int3 model_dims{0, 0, 0};
  const Image gpu_cache = image(Device::Cuda, "cache", 0, model_dims), cpu_cache = image(Device::Cpu, "cache", 0, model_dims);
  const Image gpu_network = image(Device::Cuda, "inshader", 0, model_dims);
  // at 256x192 the views read level 0 of a 128^3 decode (64 bricks of 32) through a pool of six (the root
  // and five): the second close-up evicts (three of the first's column of four), and the whole view,
  // which asks for more than fits, keeps what its frames read and reads coarser levels for the rest
  const Image gpu_small = image(Device::Cuda, "cache", 6 * 33 * 33 * 33 * sizeof(float), Int3{128, 128, 128}, 256);
  const Image gpu_network_256 = image(Device::Cuda, "inshader", 0, model_dims, 256);
  std::printf("GPU cache vs CPU cache %.1f dB, vs GPU network %.1f dB; six bricks vs the network %.1f dB\n",
              image_psnr(gpu_cache, cpu_cache), image_psnr(gpu_cache, gpu_network),
              image_psnr(gpu_small, gpu_network_256));
  EXPECT_GT(image_psnr(gpu_cache, cpu_cache), 40.0);
  EXPECT_GT(image_psnr(gpu_cache, gpu_network), 35.0);
  EXPECT_GT(image_psnr(gpu_small, gpu_network_256), 20.0);

  {  // one host cache, drawn by the GPU from its copy and by the CPU from the host's pool
    NetworkField field(*model.net, model.dims);
    BrickCacheSettings s;
    s.brick = 8;
    s.misses = CacheMisses::Coarser;
    s.decode_seconds = 100;
    s.budget_bytes = uint64_t(64) << 20;  // within any GPU's free memory (the copy refuses more than half)
    std::unique_ptr<CachedField> cache = make_model_cache(model, field, s, std::make_shared<Decoder>(model, Device::Cuda));
    const TransferFunction tf = tf_preset("ramp");
    MacroCells mc = MacroCells::single(model.dims, box_of(vol));
    mc.update(tf);
    RenderOptions o;
    o.width = 64, o.height = 48;
    o.strategy = RenderStrategy::InShader;
    GpuRenderer gpu(cache->gpu_source(), box_of(vol), mc, tf, cam, o);
    Image on_gpu, on_cpu;
    for (int f = 0; f < 6; ++f) gpu.render_frame(0, on_gpu);  // frames ask, the host cache decodes
    CpuRenderer(*cache, box_of(vol), mc, tf, cam, o).render_frame(0, on_cpu);
    std::printf("one cache, GPU copy vs host %.1f dB (%lld bricks)\n", image_psnr(on_gpu, on_cpu),
                (long long)cache->stats().resident);
    EXPECT_GT(image_psnr(on_gpu, on_cpu), 60.0);
    EXPECT_EQ(cache->stats().requested, 0);
  }
  Renderer r(model, Device::Cuda);
  r.choose_strategy("auto");
  EXPECT_STREQ(r.field().kind(), "cache");
  r.choose_strategy("auto", 0, {0, 0, 0}, 2);  // two frames: warming does not pay
  EXPECT_STREQ(r.field().kind(), "network");
}

// A renderer refreshed in place with a trainer's device parameters and new ranges (the viewer while it
// trains on the GPU) draws what a renderer built anew from the downloaded network draws, bit for bit.
TEST(GpuRender, RefreshedFromTheTrainersDeviceCopyRendersAsANewRenderer) {
  REQUIRE_GPU();
  Volume vol = blobs(Int3{32, 32, 32});
  Network net(preset_config("small"));
  const std::unique_ptr<cuda::GpuTrainer> trainer = gpu_trainer_of(net, vol);
  trainer->enable_online_ranges(vol.dims, 8);
  trainer->run(5);
  NetworkField neural(net, vol.dims);
  TransferFunction tf = tf_preset("ramp");
  MacroCells before(trainer->online_ranges(), box_of(vol));
  before.update(tf);
  const Camera cam = orbit_camera(box_of(vol), 40, 25, 30);
  for (RenderStrategy strategy : {RenderStrategy::Streaming, RenderStrategy::InShader}) {
    RenderOptions o;
    o.width = 64;
    o.height = 48;
    o.seed = 2;
    o.strategy = strategy;
    GpuRenderer refreshed(neural.gpu_source(), box_of(vol), before, tf, cam, o);
    const Image first = refreshed.render(2);
    trainer->run(100);
    MacroCells after(trainer->online_ranges(), box_of(vol));
    after.update(tf);
    ASSERT_TRUE(refreshed.refresh_network(after, trainer->device_half_params()));
    const Image img = refreshed.render(2);
    trainer->download();
    const Image fresh = GpuRenderer(neural.gpu_source(), box_of(vol), after, tf, cam, o).render(2);
    for (size_t i = 0; i < img.pixels.size(); ++i)
      ASSERT_TRUE(img.pixels[i].x == fresh.pixels[i].x && img.pixels[i].w == fresh.pixels[i].w) << "pixel " << i;
    EXPECT_LT(image_psnr(img, first), 60.0);  // training changed the picture
  }
}

// A GPU decoder refreshed in place with a trainer's device parameters (the viewer's brick cache while it
// trains on the GPU) decodes what a decoder built anew from the downloaded network decodes, bit for bit.
TEST(GpuRender, DecoderRefreshedFromTheTrainersDeviceCopyDecodesAsANewDecoder) {
  REQUIRE_GPU();
  Volume vol = blobs(Int3{32, 32, 32});
  Network net(preset_config("small"));
  const std::unique_ptr<cuda::GpuTrainer> trainer = gpu_trainer_of(net, vol);
  trainer->run(5);
  trainer->download();
  Decoder refreshed(net, Device::Cuda);
  std::vector<int64_t> index(5000);
  for (size_t i = 0; i < index.size(); ++i) index[i] = int64_t(i * 7) % vol.dims.count();
  std::vector<float> first(index.size()), got(index.size()), fresh(index.size());
  refreshed.voxels(vol.dims, index.data(), int64_t(index.size()), first.data());
  trainer->run(100);
  ASSERT_TRUE(refreshed.reload_device_params(trainer->device_half_params()));
  refreshed.voxels(vol.dims, index.data(), int64_t(index.size()), got.data());
  trainer->download();
  Decoder(net, Device::Cuda).voxels(vol.dims, index.data(), int64_t(index.size()), fresh.data());
  for (size_t i = 0; i < index.size(); ++i) ASSERT_EQ(got[i], fresh[i]) << "voxel " << index[i];
  EXPECT_NE(got, first) << "training changed the decode";
  EXPECT_FALSE(Decoder(net, Device::Cpu).reload_device_params(trainer->device_half_params()));
}
