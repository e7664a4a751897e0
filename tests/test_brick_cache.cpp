// The brick cache (fields/brick_cache.h) against independent references: with a grid as the source,
// level 0 of the cache holds the grid's own voxels, so every lookup and every image must equal the
// grid's bit for bit (cold, partly warm, warm, under a budget that evicts, SIMD packets or per ray);
// coarser levels equal a grid of the source sampled at the level's voxel centres; the level of detail
// follows the closed form of a voxel's footprint in pixels; and a trained model renders from its cache
// within the stated image PSNR of rendering its network directly; bricks decoded by the cache's own thread
// give the same images.
#include <gtest/gtest.h>
#include <hwy/targets.h>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <mutex>
#include <set>
#include <thread>
#include "vnr/error.h"
#include "vnr/core/rng.h"
#include "vnr/core/value_range_grid.h"
#include "vnr/api/model_field.h"
#include "vnr/fields/brick_cache.h"
#include "vnr/render/renderer.h"
#include "vnr/renderer.h"
#include "vnr/train/sampler.h"
#include "vnr/train/trainer.h"
#include "test_support.h"
#include "brick_cache_support.h"

using namespace vnr;
using namespace vnr::test;

namespace {

// A small hash-grid model of vol after 50 steps: a network whose decode is not the volume.
Model briefly_trained_model(const Volume& vol) {
  Model model = create_model(ModelConfig::from_json(small_hash_config(12, 16, 1)), vol);
  CpuTrainer trainer(*model.net, std::make_shared<InCoreSampler>(vol), TrainOptions{8192, 3});
  for (int i = 0; i < 50; ++i) trainer.step();
  return model;
}

}  // namespace

TEST(BrickCache, LevelZeroReadsTheGridsOwnValuesColdAndWarm) {
  Volume vol = synth(Int3{40, 36, 29});  // bricks of 8: partial bricks on every axis
  GridField grid(view_of(vol));
  CachedField cache(grid, grid_decode(vol), vol.dims, level0(8));
  Pcg32 rng(5);
  const int64_t n = 20000;
  std::vector<float> x(n), y(n), z(n), got(n);
  for (int64_t i = 0; i < n; ++i) {
    x[size_t(i)] = i < 8 ? float(i & 1) * 0.99999f : rng.next_float();  // corners: the clamped edges
    y[size_t(i)] = i < 8 ? float((i >> 1) & 1) * 0.99999f : rng.next_float();
    z[size_t(i)] = i < 8 ? float((i >> 2) & 1) * 0.99999f : rng.next_float();
  }
  cache.begin_frame(params_for(orbit_camera(box_of(vol), 0, 0, 30), vol.dims, 64, 64));
  for (int pass = 0; pass < 2; ++pass) {  // cold: every sample a miss read from the source; warm: all hits
    cache.query(x.data(), y.data(), z.data(), n, got.data());
    for (int64_t i = 0; i < n; ++i)
      ASSERT_EQ(got[size_t(i)], grid_lookup(view_of(vol), x[size_t(i)], y[size_t(i)], z[size_t(i)])) << "pass " << pass << " i " << i;
    EXPECT_EQ(cache.stats().misses, pass == 0 ? n : 0);
    cache.decode_pending();
    cache.begin_frame(params_for(orbit_camera(box_of(vol), 0, 0, 30), vol.dims, 64, 64));
  }
  EXPECT_EQ(cache.stats().resident, 5 * 5 * 4) << "every brick of level 0 was asked for once";
}

TEST(BrickCache, ImagesEqualTheGridsInEveryStrategyAndUnderAnEvictingBudget) {
  Volume vol = synth(Int3{40, 36, 32});
  GridField grid(view_of(vol));
  TransferFunction tf = tf_preset("ramp");
  MacroCells mc(value_ranges_from_grid(view_of(vol), 8), box_of(vol));
  mc.update(tf);
  RenderOptions o;
  o.width = 37, o.height = 29, o.seed = 3;
  o.strategy = RenderStrategy::InShader;
  const uint64_t brick_bytes = 9 * 9 * 9 * sizeof(float);
  for (uint64_t budget : {uint64_t(64) << 20, 3 * brick_bytes}) {
    CachedField cache(grid, grid_decode(vol), vol.dims, level0(8, budget));
    for (int frame = 0; frame < 6; ++frame) {  // the cache fills a brick a frame (and evicts under 3 bricks)
      const Camera cam = orbit_camera(box_of(vol), 35.0f + 40.0f * float(frame), 25, 30);
      for (RenderStrategy strategy : {RenderStrategy::InShader, RenderStrategy::Streaming}) {
        o.strategy = strategy;
        o.ray_packets = false;
        Image ref = CpuRenderer(grid, box_of(vol), mc, tf, cam, o).render(1);
        Image per_ray = CpuRenderer(cache, box_of(vol), mc, tf, cam, o).render(1);
        ASSERT_TRUE(same_image(per_ray, ref)) << "frame " << frame << " " << render_strategy_name(strategy);
      }
      o.strategy = RenderStrategy::InShader;
      o.ray_packets = true;
      for (int64_t t : hwy::SupportedAndGeneratedTargets()) {
        hwy::SetSupportedTargetsForTest(t);
        Image ref = CpuRenderer(grid, box_of(vol), mc, tf, cam, o).render(1);
        Image packets = CpuRenderer(cache, box_of(vol), mc, tf, cam, o).render(1);
        ASSERT_TRUE(same_image(packets, ref)) << hwy::TargetName(t) << " frame " << frame;
      }
      hwy::SetSupportedTargetsForTest(0);
    }
    const BrickCacheStats st = cache.stats();
    EXPECT_LE(st.pool_bytes, budget);
    EXPECT_GT(st.resident, 0);
    EXPECT_EQ(st.evicted, 0) << "every frame reads every brick: none is evicted while a frame needs it";
  }
}

TEST(BrickCache, TheLeastRecentlyReadBrickIsEvictedWhenTheBudgetIsFull) {
  Volume vol = synth(Int3{32, 32, 32});  // 4 x 4 x 4 bricks of 8
  GridField grid(view_of(vol));
  BrickCacheSettings s = level0(8, 2 * 9 * 9 * 9 * sizeof(float));
  s.decode_seconds = 100;  // every brick asked for, each frame
  CachedField cache(grid, grid_decode(vol), vol.dims, s);
  const RenderParams p = params_for(orbit_camera(box_of(vol), 0, 0, 30), vol.dims, 64, 64);
  cache.begin_frame(p);
  for (int k = 1; k <= 6; ++k) {  // frame k reads brick (k % 4, k / 4, 0) and brick 0 (the one to keep)
    const float x[2] = {(8.0f * float(k % 4) + 4) / 32, 4.0f / 32}, y[2] = {(8.0f * float(k / 4) + 4) / 32, 0.1f},
                z[2] = {0.1f, 0.1f};
    float v[2];
    cache.query(x, y, z, 2, v);
    for (int i = 0; i < 2; ++i) ASSERT_EQ(v[i], grid_lookup(view_of(vol), x[i], y[i], z[i]));
    cache.begin_frame(p);  // decodes what frame k asked for
    const BrickCacheStats st = cache.stats();
    EXPECT_LE(st.resident, 2);
    EXPECT_LE(st.pool_bytes, 2 * 9 * 9 * 9 * sizeof(float));
  }
  EXPECT_EQ(cache.stats().evicted, 5) << "each brick made way for the next one";
  const float x = 4.0f / 32, y = 0.1f, z = 0.1f;
  float v;
  cache.query(&x, &y, &z, 1, &v);
  EXPECT_EQ(cache.stats().misses, 0) << "brick 0, read every frame, stayed";
}

// Images while the pool evicts: two narrow views down -z through opposite columns of bricks, taken in
// turn under a budget of five bricks (a column is four), so each view's bricks make way for the other's.
// Every image still equals the grid's bit for bit: what is not cached reads the source exactly.
TEST(BrickCache, ImagesStayExactWhileThePoolEvicts) {
  Volume vol = synth(Int3{32, 32, 32});  // 4 x 4 x 4 bricks of 8
  GridField grid(view_of(vol));
  BrickCacheSettings s = level0(8, 5 * 9 * 9 * 9 * sizeof(float));
  s.decode_seconds = 100;
  CachedField cache(grid, grid_decode(vol), vol.dims, s);
  RampScene scene(vol, 16, 16);
  const TransferFunction& tf = scene.tf;
  const MacroCells& mc = scene.mc;
  RenderOptions& o = scene.o;
  for (int frame = 0; frame < 6; ++frame) {
    const float c = frame % 2 == 0 ? 4.0f : 28.0f;  // the middle of column (0, 0) or (3, 3)
    const Camera cam{Vec3f{c, c, 62}, Vec3f{c, c, 0}, Vec3f{0, 1, 0}, 5};
    for (bool packets : {false, true}) {
      o.ray_packets = packets;
      const Image img = CpuRenderer(cache, box_of(vol), mc, tf, cam, o).render(1);
      ASSERT_TRUE(same_image(img, CpuRenderer(grid, box_of(vol), mc, tf, cam, o).render(1)))
          << "frame " << frame << " packets " << packets;
    }
    EXPECT_LE(cache.stats().pool_bytes, s.budget_bytes);
  }
  EXPECT_GT(cache.stats().evicted, 0) << "the views' columns took turns in the pool";
  EXPECT_GT(cache.stats().decoded, 8) << "bricks came back after they were evicted";
}

TEST(BrickCache, CoarserMissesReadTheNearestDecodedLevel) {
  Volume vol = synth(Int3{32, 32, 32});
  GridField grid(view_of(vol));
  BrickCacheSettings s = level0(8);
  s.misses = CacheMisses::Coarser;
  CachedField cache(grid, grid_decode(vol), vol.dims, s);
  ASSERT_EQ(cache.stats().levels, 3);  // 32, 16, 8 voxels: the root is one brick
  cache.begin_frame(params_for(orbit_camera(box_of(vol), 0, 0, 30), vol.dims, 64, 64));  // decodes the root
  // The reference: the source sampled at the 8^3 centres, looked up as a grid.
  Volume root;
  root.dims = Int3{8, 8, 8};
  root.data.resize(512);
  const VoxelDecode decode = grid_decode(vol);
  std::vector<int64_t> index(512);
  for (int64_t i = 0; i < 512; ++i) index[size_t(i)] = i;
  decode(root.dims, index.data(), 512, root.data.data());
  Pcg32 rng(9);
  for (int i = 0; i < 1000; ++i) {
    const float x = rng.next_float(), y = rng.next_float(), z = rng.next_float();
    float v;
    cache.query(&x, &y, &z, 1, &v);
    ASSERT_EQ(v, grid_lookup(view_of(root), x, y, z));
  }
  EXPECT_EQ(cache.stats().misses, 0) << "no sample reads the source once the root is in";
}

TEST(BrickCache, LevelOfDetailFollowsTheVoxelFootprint) {
  // 128^3 voxels, bricks of 8: levels of 128, 64, 32, 16 and 8 voxels. The camera looks down -z at the
  // middle of the +z face from distance D; one pixel there spans D * 2 tan(15 deg) / H voxels, and a
  // sample reads the coarsest level whose voxels (2^l) are at most that wide.
  const Int3 dims{128, 128, 128};
  Volume vol = synth(Int3{8, 8, 8});
  GridField grid(view_of(vol));
  BrickCacheSettings s;
  s.brick = 8;
  CachedField cache(grid, grid_decode(vol), dims, s);
  const int H = 100;
  for (float pixel_voxels : {0.7f, 1.5f, 2.5f, 4.5f, 9.0f, 40.0f}) {
    const float D = pixel_voxels * float(H) / (2 * std::tan(15.0f * 3.14159265f / 180));
    const Camera cam{Vec3f{64, 64, 128 + D}, Vec3f{64, 64, 0}, Vec3f{0, 1, 0}, 30};
    cache.begin_frame(params_for(cam, dims, H, H));
    const int expect = std::min(4, pixel_voxels < 2 ? 0 : int(std::floor(std::log2(pixel_voxels))));
    EXPECT_EQ(cache.view().level_at(0.5f, 0.5f, 0.999f), expect) << pixel_voxels << " voxels a pixel";
    // The lookups' shortcut: the whole box reads level 0 unblended only where even its far corner
    // (sqrt(64^2 + 64^2 + (D + 128)^2) away) is short of level 0's blend.
    const bool level0 = cache.view().box_reads_level0();
    EXPECT_EQ(level0, pixel_voxels < 1) << pixel_voxels << " voxels a pixel";
    EXPECT_EQ(cache.view().level0_only, level0) << "decided with the view";
    for (int i = 0; level0 && i < 1000; ++i) {
      float t = 1;
      const float u[3] = {float(i % 10) / 9, float(i / 10 % 10) / 9, float(i / 100) / 9};
      EXPECT_EQ(cache.view().level_at(u[0], u[1], u[2], &t), 0);
      EXPECT_EQ(t, 0.0f);
    }
  }
  EXPECT_EQ(cache_level_dims(Int3{100, 64, 1}, 3), (Int3{13, 8, 1}));
  EXPECT_EQ(cache_level_dims(Int3{100, 64, 1}, 40), (Int3{1, 1, 1}));
}

TEST(BrickCache, RejectsBadSettingsWithOneClearError) {
  Volume vol = synth(Int3{16, 16, 16});
  GridField grid(view_of(vol));
  BrickCacheSettings s;
  s.brick = 12;
  EXPECT_THROW(CachedField(grid, grid_decode(vol), vol.dims, s), Error);
  s.brick = 8;
  s.budget_bytes = 100;  // less than one brick
  EXPECT_THROW(CachedField(grid, grid_decode(vol), vol.dims, s), Error);
  s.budget_bytes = uint64_t(64) << 20;  // an index of 512^3 bricks (16384^3 voxels) would need ~2 GiB
  EXPECT_THROW(CachedField(grid, grid_decode(vol), Int3{16384, 16384, 16384}, s), Error);
  EXPECT_EQ(parse_cache_budget("512MiB"), uint64_t(512) << 20);
  EXPECT_EQ(parse_cache_budget("auto"), default_cache_budget());
  EXPECT_THROW(parse_cache_budget("lots"), Error);
}

TEST(BrickCache, ATrainedModelRendersFromItsCacheAsItsNetworkDoes) {
  Volume vol = synth(Int3{32, 32, 32});
  Model model = create_model(ModelConfig::from_json(small_hash_config(14, 32, 2)), vol);
  CpuTrainer trainer(*model.net, std::make_shared<InCoreSampler>(vol), TrainOptions{16384, 3});
  for (int i = 0; i < 200; ++i) trainer.step();
  Renderer direct(model, Device::Cpu), cached(model, Device::Cpu);
  for (Renderer* r : {&direct, &cached}) {
    r->set_size(64, 64);
    r->set_camera(orbit_camera(r->box(), 40, 25, 30));
    r->set_macrocells(MacroCellMode::Off);
  }
  direct.choose_strategy("streaming");
  cached.choose_strategy("auto");  // a model on the CPU: the cache
  ASSERT_TRUE(cached.cache().has_value());
  EXPECT_STREQ(cached.field().kind(), "cache");
  cached.warm_cache();
  for (int f = 0; f < 4; ++f) direct.render_frame(), cached.render_frame();
  const double psnr = compare_images(cached.image(), direct.image()).psnr;
  std::printf("image PSNR of the cached model against its network: %.2f dB\n", psnr);
  EXPECT_GT(psnr, 40.0);
  EXPECT_EQ(cached.cache_stats().misses, 0) << "a warm cache answers the whole view";
  // What vnr bench render times: an orbit from a cache warmed at its every camera reads no network.
  RenderStats orbit_stats;
  RenderOptions orbit_options = cached.options();
  orbit_options.strategy = RenderStrategy::InShader;
  const double fps = orbit_frame_rate(cached, orbit_options, MacroCellMode::Off, RenderOrbit{3, 0, 20, 30, 16},
                                      BrickCacheSettings{}, &orbit_stats);
  EXPECT_GT(fps, 0);
  EXPECT_EQ(orbit_stats.frames, 3);
  EXPECT_EQ(cached.cache_stats().misses, 0);
  EXPECT_THROW(orbit_frame_rate(cached, orbit_options, MacroCellMode::Off, RenderOrbit{0, 0, 20, 30, 16}, std::nullopt,
                                &orbit_stats),
               Error);
  EXPECT_THROW(cached.choose_strategy("fastest"), Error);
  cached.choose_strategy("auto", 0, Int3{0, 0, 0}, 1);  // one frame: warming would cost more than it saves
  EXPECT_FALSE(cached.cache().has_value());
  EXPECT_STREQ(cached.field().kind(), "network");
  Renderer volume_renderer(vol, Device::Cpu);
  EXPECT_THROW(volume_renderer.choose_strategy("cache"), Error);
  volume_renderer.choose_strategy("auto");
  EXPECT_FALSE(volume_renderer.cache().has_value()) << "a volume is drawn directly";
}

TEST(BrickCache, UnderATinyBudgetCoarserLevelsCoverEverySample) {
  Volume vol = synth(Int3{40, 36, 32});
  GridField grid(view_of(vol));
  BrickCacheSettings s = level0(8, 3 * 9 * 9 * 9 * sizeof(float));  // the root and two bricks
  s.misses = CacheMisses::Coarser;
  s.decode_seconds = 100;
  CachedField cache(grid, grid_decode(vol), vol.dims, s);
  RampScene scene(vol, 48, 40);
  const TransferFunction& tf = scene.tf;
  const MacroCells& mc = scene.mc;
  const RenderOptions& o = scene.o;
  for (int frame = 0; frame < 4; ++frame) {
    const Camera cam = orbit_camera(box_of(vol), 30.0f + 50.0f * float(frame), 20, 30);
    Image img = CpuRenderer(cache, box_of(vol), mc, tf, cam, o).render(1);
    Image ref = CpuRenderer(grid, box_of(vol), mc, tf, cam, o).render(1);
    EXPECT_EQ(cache.stats().misses, 0) << "no hole: every sample read a decoded level";
    EXPECT_GT(compare_images(img, ref).psnr, 20.0) << "coarser levels look like the volume";
    EXPECT_LE(cache.stats().pool_bytes, s.budget_bytes);
  }
}

TEST(BrickCache, AModelsCacheEqualsItsDecodeAndRendersAsTheDecodedGrid) {
  Volume vol = synth(Int3{28, 24, 20});
  Model model = briefly_trained_model(vol);
  NetworkField field(*model.net, model.dims);
  BrickCacheSettings s = level0(8);
  s.decode_seconds = 100;
  std::unique_ptr<CachedField> cache = make_model_cache(model, field, s, std::make_shared<Decoder>(model, Device::Cpu));
  Volume decoded;
  decoded.dims = model.dims;
  decoded.data.resize(size_t(model.dims.count()));
  Decoder(model, Device::Cpu).slices(model.dims, 0, model.dims.z, decoded.data.data());
  GridField grid(view_of(decoded));
  TransferFunction tf = tf_preset("ramp");
  MacroCells mc = MacroCells::single(model.dims, box_of(vol));
  mc.update(tf);
  RenderOptions o;
  o.width = 40, o.height = 32;
  o.strategy = RenderStrategy::InShader;
  const Camera cam = orbit_camera(box_of(vol), 25, 15, 30);
  cache->begin_frame(params_for(cam, model.dims, o.width, o.height));
  Pcg32 rng(4);
  std::vector<float> x(3000), y(3000), z(3000), v(3000);
  for (size_t i = 0; i < x.size(); ++i) x[i] = rng.next_float(), y[i] = rng.next_float(), z[i] = rng.next_float();
  cache->query(x.data(), y.data(), z.data(), int64_t(x.size()), v.data());  // asks for every brick
  cache->decode_pending();
  cache->begin_frame(params_for(cam, model.dims, o.width, o.height));
  cache->query(x.data(), y.data(), z.data(), int64_t(x.size()), v.data());
  EXPECT_EQ(cache->stats().misses, 0);
  for (size_t i = 0; i < x.size(); ++i) ASSERT_EQ(v[i], grid_lookup(view_of(decoded), x[i], y[i], z[i])) << i;
  for (bool packets : {false, true}) {
    o.ray_packets = packets;
    EXPECT_TRUE(same_image(CpuRenderer(*cache, box_of(vol), mc, tf, cam, o).render(2),
                           CpuRenderer(grid, box_of(vol), mc, tf, cam, o).render(2)))
        << "packets " << packets;
  }
}

// A coarser level of a model's cache holds the model decoded at that level's dims: with every voxel of
// every level under the footprint allowed, samples read the root (7 x 6 x 5 of 28 x 24 x 20), exactly
// as a grid over Decoder's decode at 7 x 6 x 5.
TEST(BrickCache, AModelsCoarserLevelsEqualItsDecodeAtTheirDims) {
  Volume vol = synth(Int3{28, 24, 20});
  Model model = briefly_trained_model(vol);
  NetworkField field(*model.net, model.dims);
  BrickCacheSettings s = level0(8);
  s.lod_pixels = 1e9f;  // a voxel of any level covers fewer pixels: the coarsest level everywhere
  s.decode_seconds = 100;
  std::unique_ptr<CachedField> cache = make_model_cache(model, field, s, std::make_shared<Decoder>(model, Device::Cpu));
  ASSERT_EQ(cache->stats().levels, 3);  // 28 x 24 x 20, 14 x 12 x 10, 7 x 6 x 5
  const RenderParams p = params_for(orbit_camera(box_of(vol), 25, 15, 30), model.dims, 40, 32);
  cache->begin_frame(p);
  EXPECT_EQ(cache->view().level_at(0.5f, 0.5f, 0.5f), 2);
  Volume root;
  root.dims = Int3{7, 6, 5};
  root.data.resize(size_t(root.dims.count()));
  Decoder(model, Device::Cpu).slices(root.dims, 0, root.dims.z, root.data.data());
  Pcg32 rng(8);
  std::vector<float> x(2000), y(2000), z(2000), v(2000);
  for (size_t i = 0; i < x.size(); ++i) x[i] = rng.next_float(), y[i] = rng.next_float(), z[i] = rng.next_float();
  cache->query(x.data(), y.data(), z.data(), int64_t(x.size()), v.data());  // asks for the root
  cache->decode_pending();
  cache->begin_frame(p);
  cache->query(x.data(), y.data(), z.data(), int64_t(x.size()), v.data());
  EXPECT_EQ(cache->stats().misses, 0);
  for (size_t i = 0; i < x.size(); ++i) ASSERT_EQ(v[i], grid_lookup(view_of(root), x[i], y[i], z[i])) << i;
}

TEST(BrickCache, BricksUnderTheCursorAreDecodedFirst) {
  Volume vol = synth(Int3{32, 32, 32});  // 4 x 4 x 4 bricks of 8
  GridField grid(view_of(vol));
  CachedField cache(grid, grid_decode(vol), vol.dims, level0(8));  // one brick a frame
  const RenderParams p = params_for(orbit_camera(box_of(vol), 0, 0, 30), vol.dims, 64, 64);
  cache.begin_frame(p);
  std::vector<float> x, y, z;
  for (int k = 0; k < 4; ++k)
    for (int j = 0; j < 4; ++j)
      for (int i = 0; i < 4; ++i) x.push_back((8.0f * i + 4) / 32), y.push_back((8.0f * j + 4) / 32), z.push_back((8.0f * k + 4) / 32);
  std::vector<float> v(64);
  cache.query(x.data(), y.data(), z.data(), 64, v.data());  // asks for all 64
  // The cursor's ray runs along x through the centres of the bricks (i, 2, 3).
  cache.set_focus(std::make_pair(Vec3f{-50, 20, 28}, Vec3f{1, 0, 0}));
  cache.begin_frame(p);
  ASSERT_EQ(cache.stats().resident, 1);
  const float on_x[4] = {4.0f / 32, 12.0f / 32, 20.0f / 32, 28.0f / 32}, on_y[4] = {0.625f, 0.625f, 0.625f, 0.625f},
              on_z[4] = {0.875f, 0.875f, 0.875f, 0.875f};
  float got[4];
  cache.query(on_x, on_y, on_z, 4, got);
  EXPECT_EQ(cache.stats().misses, 3) << "one of the four bricks on the ray came first";
  const float far_x = 0.9f, far_y = 0.1f, far_z = 0.1f;
  cache.query(&far_x, &far_y, &far_z, 1, got);
  EXPECT_EQ(cache.stats().misses, 4) << "a brick off the ray waits";
}

TEST(BrickCache, PacketsStraddlingLevelsGiveThePerRayImage) {
  const Volume vol = synth(Int3{96, 80, 64});  // bricks of 8: levels of 96, 48, 24, 12 and 6 voxels
  GridField grid(view_of(vol));
  BrickCacheSettings s;
  s.brick = 8;
  s.lod_pixels = 1.2f;  // a voxel footprint of 4 pixels (levels 1 | 2) falls inside the volume at this view
  s.decode_seconds = 100;
  CachedField cache(grid, grid_decode(vol), vol.dims, s);
  TransferFunction tf = tf_preset("ramp");
  MacroCells mc = MacroCells::single(vol.dims, box_of(vol));
  mc.update(tf);
  const Camera cam = orbit_camera(box_of(vol), 30, 20, 30);
  RenderOptions o;
  o.width = 48, o.height = 40;
  o.strategy = RenderStrategy::InShader;
  o.ray_packets = false;
  CpuRenderer(cache, box_of(vol), mc, tf, cam, o).render(1);  // asks for the view's bricks
  const Image ref = CpuRenderer(cache, box_of(vol), mc, tf, cam, o).render(1);  // decodes them, then reads them
  // The view reads more than one level.
  const RenderParams p = params_for(cam, vol.dims, o.width, o.height);
  std::set<int> levels;
  for (float z : {0.05f, 0.5f, 0.95f})
    for (float x : {0.05f, 0.95f}) levels.insert(cache.view().level_at(x, 0.5f, z));
  ASSERT_GE(levels.size(), 2u) << "the camera " << p.cam.eye.z << " sees two levels";
  int blended = 0;  // and samples that mix two levels (the packets' blend against the scalar one)
  for (int i = 0; i < 1000; ++i) {
    float t = 0;
    cache.view().level_at(float(i % 10) / 10 + 0.05f, float(i / 10 % 10) / 10 + 0.05f, float(i / 100) / 10 + 0.05f, &t);
    blended += t > 0;
  }
  ASSERT_GT(blended, 50);
  EXPECT_EQ(cache.stats().misses, 0);
  o.ray_packets = true;
  for (int64_t t : hwy::SupportedAndGeneratedTargets()) {
    hwy::SetSupportedTargetsForTest(t);
    EXPECT_TRUE(same_image(CpuRenderer(cache, box_of(vol), mc, tf, cam, o).render(1), ref)) << hwy::TargetName(t);
  }
  hwy::SetSupportedTargetsForTest(0);
}

// Asynchronous decoding: begin_frame hands the requests to the cache's decoding thread and returns without
// decoding (the decode is held at a gate here, so this is not a race with the clock); frames meanwhile
// read the source (exact images); once the thread is let go, the bricks come in on it, not on the frame's
// thread, and images equal the grid's. set_asynchronous(false) returns only with no decode in flight.
TEST(BrickCache, TheDecodingThreadFillsTheCacheWhileFramesRender) {
  Volume vol = synth(Int3{40, 36, 32});
  GridField grid(view_of(vol));
  RampScene scene(vol, 37, 29);
  std::mutex mu;
  std::condition_variable cv;
  bool open = false;
  std::set<std::thread::id> decoders;
  std::atomic<int> running{0};
  const VoxelDecode plain = grid_decode(vol);
  VoxelDecode gated = [&](Int3 dims, const int64_t* index, int64_t n, float* out) {
    running += 1;
    {
      std::unique_lock<std::mutex> lock(mu);
      cv.wait(lock, [&] { return open; });
      decoders.insert(std::this_thread::get_id());
    }
    plain(dims, index, n, out);
    running -= 1;
  };
  CachedField cache(grid, gated, vol.dims, level0(8));
  cache.set_asynchronous(true);
  const Camera cam = orbit_camera(box_of(vol), 35, 25, 30);
  const Image ref = CpuRenderer(grid, box_of(vol), scene.mc, scene.tf, cam, scene.o).render(1);
  CpuRenderer from_cache(cache, box_of(vol), scene.mc, scene.tf, cam, scene.o);
  for (int frame = 0; frame < 3; ++frame) {  // the thread waits at the gate: no frame decodes a brick
    ASSERT_TRUE(same_image(from_cache.render(1), ref)) << "frame " << frame;
    EXPECT_EQ(cache.stats().resident, 0);
  }
  EXPECT_GT(cache.stats().requested, 0);
  {
    std::lock_guard<std::mutex> lock(mu);
    open = true;
  }
  cv.notify_all();
  for (int frame = 0; frame < 200 && cache.stats().requested > 0; ++frame) {
    cache.wait_for_bricks(1.0);
    ASSERT_TRUE(same_image(from_cache.render(1), ref)) << "frame " << frame;
  }
  // The bricks the view reads, as a cache decoding in its frames gets them.
  CachedField in_frames(grid, plain, vol.dims, level0(8));
  CpuRenderer(in_frames, box_of(vol), scene.mc, scene.tf, cam, scene.o).render(1);
  in_frames.decode_pending();
  const BrickCacheStats st = cache.stats();
  EXPECT_EQ(st.requested, 0);
  EXPECT_EQ(st.resident, in_frames.stats().resident) << "every brick the view reads, decoded once";
  EXPECT_EQ(st.decoded, st.resident);
  EXPECT_EQ(st.misses, 0) << "the last frame read the cache alone";
  ASSERT_TRUE(same_image(from_cache.render(1), ref));
  EXPECT_EQ(decoders.size(), 1u);
  EXPECT_EQ(decoders.count(std::this_thread::get_id()), 0u) << "decoded on the cache's thread, not the frame's";
  cache.set_asynchronous(false);
  EXPECT_EQ(running.load(), 0);
}

// Levels of detail blend (brick_cache_view.h, kLodBlendStart): as the camera backs away from a point, its
// value moves from level 0 to level 1 continuously: no jump where the blend starts (footprint 2^(3/4)
// voxels a pixel) nor where level 1 takes over (2), though the two levels differ there (the seam the
// per-brick rule showed).
TEST(BrickCache, LevelsOfDetailBlendWithoutASeam) {
  Volume vol;  // noise: levels 0 and 1 (bricks of 8: levels of 96, 48, 24, 12 and 6 voxels) differ
  vol.dims = Int3{96, 80, 64};
  vol.data.resize(size_t(vol.dims.count()));
  Pcg32 rng(3);
  for (float& v : vol.data) v = rng.next_float();
  GridField grid(view_of(vol));
  BrickCacheSettings s;
  s.brick = 8;
  CachedField cache(grid, grid_decode(vol), vol.dims, s);
  const int H = 100;
  const float x = 0.43f, y = 0.57f, z = 0.61f;
  const Vec3f at{x * 96, y * 80, z * 64};
  auto value_at = [&](float footprint) {  // level-0 voxels a pixel at the point
    const float d = footprint * float(H) / (2 * std::tan(15.0f * 3.14159265f / 180));
    const RenderParams p = params_for(Camera{Vec3f{at.x, at.y, at.z + d}, at, Vec3f{0, 1, 0}, 30}, vol.dims, H, H);
    float v = 0;
    for (int pass = 0; pass < 2; ++pass) {  // asks for its bricks, then reads them
      cache.begin_frame(p);
      cache.query(&x, &y, &z, 1, &v);
      cache.decode_pending();
    }
    EXPECT_EQ(cache.stats().misses, 0);
    return v;
  };
  const float level0 = grid_lookup(view_of(vol), x, y, z);
  const float level1 = value_at(2.5f);  // inside level 1's range, before its blend with level 2
  const float jump = std::fabs(level1 - level0);
  ASSERT_GT(jump, 0.01f) << "the levels differ at this point";
  EXPECT_EQ(value_at(1.6f), level0);
  EXPECT_LT(std::fabs(value_at(kLodBlendStart * 1.0005f) - level0), 0.01f * jump);
  EXPECT_LT(std::fabs(value_at(1.999f) - level1), 0.01f * jump);
  EXPECT_EQ(value_at(2.001f), level1);
  // Between, the value moves monotonically from one level to the other.
  float last = level0;
  for (float f = kLodBlendStart; f <= 2.0f; f += (2.0f - kLodBlendStart) / 8) {
    const float v = value_at(f);
    EXPECT_GE((v - last) * (level1 - level0), -1e-7f) << f;
    last = v;
  }
}
