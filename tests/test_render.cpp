// Rendering against closed forms and cross-checks: the DDA against brute force, macro-cell ranges,
// ray marching a constant field (closed-form emission-absorption), path tracing a homogeneous medium
// (analytic transmittance), streaming == in-shader, macro-cells on == off, grid vs trained model.
#include <gtest/gtest.h>
#include <hwy/targets.h>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <functional>
#include <sstream>
#include <string>
#include "vnr/error.h"
#include "vnr/core/parallel.h"
#include "vnr/core/rng.h"
#include "vnr/core/value_range_grid.h"
#include "vnr/fields/grid_packets.h"
#include "vnr/render/renderer.h"
#include "vnr/render/tiles.h"
#include "vnr/train/model_io.h"
#include "vnr/train/sampler.h"
#include "vnr/train/trainer.h"
#include "vnr/volume_writer.h"
#include "render_support.h"
#include "test_support.h"

using namespace vnr;
using namespace vnr::test;

namespace {

TransferFunction constant_tf(Vec3f rgb, float alpha) {
  TransferFunction tf;
  tf.table.assign(16, Vec4f{rgb.x, rgb.y, rgb.z, alpha});
  return tf;
}

double image_psnr(const Image& a, const Image& b) { return compare_images(a, b).psnr; }

}  // namespace

TEST(Dda, VisitsTheCellsABruteForceWalkVisits) {
  Pcg32 rng(7);
  ValueRangeGrid g(Int3{40, 33, 20}, 8);  // 5 x 5 x 3 cells, the last ones overhanging
  MacroCells mc(g, Vec3f{40, 33, 20});
  MacroCellView v = mc.view();
  for (int trial = 0; trial < 300; ++trial) {
    Vec3f org{rng.next_float() * 120 - 40, rng.next_float() * 100 - 33, rng.next_float() * 60 - 20};
    Vec3f dir = normalize(Vec3f{rng.next_float() - 0.5f, rng.next_float() - 0.5f, rng.next_float() - 0.5f});
    if (trial % 10 == 0) dir = Vec3f{0, 0, trial % 20 == 0 ? 1.0f : -1.0f};  // axis-parallel rays
    float t0, t1;
    if (!intersect_box(org, dir, Vec3f{40, 33, 20}, &t0, &t1)) continue;
    DdaState s;
    dda_init(v, org, dir, t0, t1, s);
    float t = t0;
    int guard = 0;
    for (;;) {
      float te = dda_cell_exit(s);
      ASSERT_GE(te, t - 1e-4f);
      // the midpoint of the segment lies in the cell the DDA reports
      Vec3f p = org + dir * (0.5f * (t + te));
      if (te - t > 1e-3f) {
        EXPECT_EQ(s.cell[0], std::clamp(int(std::floor(p.x / 8)), 0, 4)) << trial;
        EXPECT_EQ(s.cell[1], std::clamp(int(std::floor(p.y / 8)), 0, 4)) << trial;
        EXPECT_EQ(s.cell[2], std::clamp(int(std::floor(p.z / 8)), 0, 2)) << trial;
      }
      t = te;
      if (!dda_advance(v, s)) break;
      ASSERT_LT(++guard, 100);
    }
    EXPECT_NEAR(t, t1, 1e-3f) << "the segments cover the ray up to the box exit";
  }
}

TEST(MacroCells, GridRangesEqualPerVoxelWidening) {
  Volume vol = synth(Int3{37, 20, 18});
  ValueRangeGrid fast = value_ranges_from_grid(view_of(vol), 8);
  ValueRangeGrid slow(vol.dims, 8);
  for (int64_t z = 0; z < vol.dims.z; ++z)
    for (int64_t y = 0; y < vol.dims.y; ++y)
      for (int64_t x = 0; x < vol.dims.x; ++x)
        slow.add(x + 0.5f, y + 0.5f, z + 0.5f, vol.data[x + vol.dims.x * (y + vol.dims.y * z)]);
  ASSERT_EQ(fast.count(), 5 * 3 * 3);
  for (int64_t c = 0; c < fast.count(); ++c) {
    EXPECT_EQ(fast.lo[c], slow.lo[c]);
    EXPECT_EQ(fast.hi[c], slow.hi[c]);
  }
  // every interpolated value inside a cell is within its range
  Pcg32 rng(3);
  for (int i = 0; i < 20000; ++i) {
    float u[3] = {rng.next_float(), rng.next_float(), rng.next_float()};
    float val = grid_lookup(view_of(vol), u[0], u[1], u[2]);
    int64_t cx = int64_t(u[0] * 37) / 8, cy = int64_t(u[1] * 20) / 8, cz = int64_t(u[2] * 18) / 8;
    int64_t c = cx + 5 * (cy + 3 * cz);
    EXPECT_GE(val, fast.lo[c] - 1e-6f);
    EXPECT_LE(val, fast.hi[c] + 1e-6f);
  }
  // the model-file encoding round-trips, empty cells included
  ValueRangeGrid partial(vol.dims, 8);
  partial.add(3, 3, 3, 0.25f);
  ValueRangeGrid back = ValueRangeGrid::from_pairs(vol.dims, partial.cells, partial.to_pairs());
  EXPECT_EQ(back.cell_size, 8);
  for (int64_t c = 0; c < partial.count(); ++c) {
    EXPECT_EQ(back.empty(c), partial.empty(c));
    if (!partial.empty(c)) EXPECT_EQ(back.lo[c], 0.25f);
  }
}

TEST(MacroCells, MaxOpacityFollowsTheTransferFunction) {
  ValueRangeGrid g(Int3{32, 32, 32}, 16);
  g.add(4, 4, 4, 0.05f);     // cell 0: only low values
  g.add(28, 4, 4, 0.9f);     // cell 1: high values
  // cells 2.. stay empty
  MacroCells mc(g, Vec3f{32, 32, 32});
  mc.update(tf_preset("ramp"));  // opacity 0 up to 0.1, then a ramp to 0.8
  const auto& m = mc.max_opacity();
  EXPECT_EQ(m[0], 0.0f) << "0.05 +- one table entry is below the ramp";
  EXPECT_NEAR(m[1], tf_lookup(view_of(tf_preset("ramp")), 0.9f).w, 2e-3f);
  for (size_t c = 2; c < m.size(); ++c) EXPECT_EQ(m[c], 0.0f);
}

TEST(MacroCells, OnlineRangesCoverEveryRegionTheDataOccupies) {
  // A blob in one corner: the cells it reaches must be non-transparent with online ranges built from
  // training batches, exactly like with the precomputed ranges.
  Volume vol = make_volume(Int3{48, 48, 48}, [](float x, float y, float z) {
    float r2 = (x - 0.3f) * (x - 0.3f) + (y - 0.35f) * (y - 0.35f) + (z - 0.3f) * (z - 0.3f);
    return std::exp(-r2 * 40.0f);
  });
  Network net(Json{{"encoding", {{"otype", "HashGrid"}, {"n_levels", 2}, {"n_features_per_level", 2},
                                  {"log2_hashmap_size", 10}, {"base_resolution", 4}}},
                   {"network", {{"otype", "FullyFusedMLP"}, {"n_neurons", 16}, {"n_hidden_layers", 1}}},
                   {"loss", {{"otype", "L2"}}}});
  net.init_params(1);
  CpuTrainer trainer(net, std::make_shared<InCoreSampler>(vol), TrainOptions{16384, 5});
  trainer.enable_online_ranges(vol.dims, 8);
  for (int i = 0; i < 12; ++i) trainer.step();
  ValueRangeGrid online = trainer.online_ranges();
  ValueRangeGrid exact = value_ranges_from_grid(view_of(vol), 8);
  TransferFunction tf = tf_preset("ramp");
  MacroCells a(online, box_of(vol)), b(exact, box_of(vol));
  a.update(tf);
  b.update(tf);
  int occupied = 0;
  for (int64_t c = 0; c < exact.count(); ++c) {
    EXPECT_FALSE(online.empty(c)) << "every cell is sampled";
    if (b.max_opacity()[c] > 0.05f) {
      ++occupied;
      EXPECT_GT(a.max_opacity()[c], 0.0f) << "cell " << c << " holds data but is transparent online";
    }
  }
  EXPECT_GT(occupied, 4);
}

TEST(RayMarch, ConstantFieldMatchesTheClosedForm) {
  // Emission-absorption with per-voxel opacity a0 over a path of length L: A = 1 - (1 - a0)^L and the
  // premultiplied colour is c * A, whatever the step sizes (the opacity correction telescopes).
  Volume vol = make_volume(Int3{24, 20, 30}, [](float, float, float) { return 0.5f; });
  GridField field(view_of(vol));
  const float a0 = 0.04f;
  const Vec3f c{0.2f, 0.6f, 0.9f};
  TransferFunction tf = constant_tf(c, a0);
  for (float step_max : {1.0f, 16.0f}) {
    for (int cells : {0, 1}) {
      MacroCells mc = cells ? MacroCells(value_ranges_from_grid(view_of(vol), 4), box_of(vol))
                            : MacroCells::single(vol.dims, box_of(vol));
      mc.update(tf);
      RenderOptions o;
      o.width = o.height = 9;
      o.step = 0.7f;
      o.step_max = step_max;
      Camera cam{Vec3f{12, 10, 200}, Vec3f{12, 10, 15}, Vec3f{0, 1, 0}, 1.0f};  // centre ray along -z
      CpuRenderer r(field, box_of(vol), mc, tf, cam, o);
      Image img = r.render(1);
      const Vec4f p = img.at(4, 4);
      const double A = 1 - std::pow(1 - a0, 30.0);
      EXPECT_NEAR(p.w, A, 2e-4) << "step_max " << step_max << " cells " << cells;
      EXPECT_NEAR(p.x, c.x * A, 2e-4);
      EXPECT_NEAR(p.y, c.y * A, 2e-4);
      EXPECT_NEAR(p.z, c.z * A, 2e-4);
    }
  }
}

TEST(PathTrace, HomogeneousMediumMatchesTheAnalyticTransmittance) {
  // Black albedo: a path that collides contributes nothing, one that crosses the box unscattered sees
  // the white background, so E[pixel] = exp(-sigma * L).
  Volume vol = make_volume(Int3{16, 16, 40}, [](float, float, float) { return 0.5f; });
  GridField field(view_of(vol));
  const float a0 = 0.025f, density = 1.0f;
  TransferFunction tf = constant_tf(Vec3f{0, 0, 0}, a0);
  for (int cells : {0, 1}) {
    MacroCells mc = cells ? MacroCells(value_ranges_from_grid(view_of(vol), 8), box_of(vol))
                          : MacroCells::single(vol.dims, box_of(vol));
    mc.update(tf);
    RenderOptions o;
    o.mode = RenderMode::PathTrace;
    o.width = o.height = 16;
    o.background = Vec3f{1, 1, 1};
    o.density_scale = density;
    o.seed = 11;
    Camera cam{Vec3f{8, 8, 4000}, Vec3f{8, 8, 20}, Vec3f{0, 1, 0}, 0.05f};  // nearly parallel rays along -z
    CpuRenderer r(field, box_of(vol), mc, tf, cam, o);
    Image img = r.render(64);
    double mean = 0;
    for (const Vec4f& p : img.pixels) mean += p.x;
    mean /= double(img.pixels.size());
    const double expected = std::exp(-a0 * density * 40.0);  // 0.368
    const double sd = std::sqrt(expected * (1 - expected) / (16.0 * 16 * 64));
    EXPECT_NEAR(mean, expected, 4 * sd) << "macro-cells " << cells;
  }
}

TEST(Strategies, StreamingAndInShaderGiveTheSameImageOnTheGrid) {
  const GridScene scene;
  for (RenderMode mode : {RenderMode::RayMarch, RenderMode::Shadow, RenderMode::PathTrace}) {
    for (bool shade : {false, true}) {
      if (shade && mode != RenderMode::RayMarch) continue;
      Image img[2];
      for (int s = 0; s < 2; ++s) {
        RenderOptions o;
        o.mode = mode;
        o.shade = shade;
        o.strategy = s ? RenderStrategy::InShader : RenderStrategy::Streaming;
        o.width = 48;
        o.height = 40;
        o.seed = 5;
        o.samples_per_iteration = 3;
        CpuRenderer r(scene.field, box_of(scene.vol), scene.mc, scene.tf, scene.cam, o);
        img[s] = r.render(2);
      }
      double sum = 0;
      for (size_t i = 0; i < img[0].pixels.size(); ++i) {
        const Vec4f &a = img[0].pixels[i], &b = img[1].pixels[i];
        ASSERT_EQ(a.x, b.x) << render_mode_name(mode) << " pixel " << i;
        ASSERT_EQ(a.y, b.y);
        ASSERT_EQ(a.z, b.z);
        ASSERT_EQ(a.w, b.w);
        sum += a.x + a.y + a.z;
      }
      EXPECT_GT(sum, 10.0) << "the image is not empty";
    }
  }
}

// What a viewer shows: render_mean_rgba8 over frames 0..f gives the bytes of render(f + 1), the mean of the
// same frames; a first call at a later frame starts the mean with that frame alone.
TEST(CpuRenderer, MeanOfFramesAsRgba8IsTheAccumulatedImage) {
  const GridScene scene;
  RenderOptions o;
  o.mode = RenderMode::PathTrace;  // every frame differs
  o.width = 37;
  o.height = 29;
  CpuRenderer r(scene.field, box_of(scene.vol), scene.mc, scene.tf, scene.cam, o);
  std::vector<uint8_t> rgba;
  for (uint32_t f = 0; f < 4; ++f) {
    r.render_mean_rgba8(f, rgba);
    CpuRenderer fresh(scene.field, box_of(scene.vol), scene.mc, scene.tf, scene.cam, o);
    EXPECT_EQ(rgba, to_rgba8(fresh.render(int(f) + 1))) << "frame " << f;
  }
  CpuRenderer late(scene.field, box_of(scene.vol), scene.mc, scene.tf, scene.cam, o);
  Image third;
  r.render_frame(3, third);
  late.render_mean_rgba8(3, rgba);
  EXPECT_EQ(rgba, to_rgba8(third));
}

// Tiles claimed from a shared counter: two cursors (threads) interleaving their claims visit every pixel
// of an image that is not a multiple of the tile size exactly once.
TEST(Tiles, ClaimedTilesCoverEveryPixelOnce) {
  const int W = 37, H = 21;
  std::atomic<int64_t> next{0};
  TileCursor a{W, H, 8, 0, 1, &next}, b{W, H, 8, 0, 1, &next};
  std::vector<int> seen(size_t(W) * H, 0);
  bool more_a = true, more_b = true;
  for (int turn = 0; more_a || more_b; ++turn) {
    int x, y;
    TileCursor& c = turn % 3 == 0 ? b : a;  // uneven turns: b claims fewer tiles
    bool& more = turn % 3 == 0 ? more_b : more_a;
    if (more && (more = c.next(&x, &y))) ++seen[size_t(y) * W + x];
  }
  for (int v : seen) ASSERT_EQ(v, 1);
}

// Work is claimed by whichever thread is free, so the image must not depend on the thread count:
// in-shader (per ray and SIMD packets) and streaming, bit for bit on 1, 2 and 3 threads.
TEST(Strategies, ImagesDoNotDependOnTheThreadCount) {
  const GridScene scene;
  for (RenderStrategy strategy : {RenderStrategy::InShader, RenderStrategy::Streaming})
    for (bool packets : {false, true}) {
      if (packets && strategy != RenderStrategy::InShader) continue;
      std::vector<Image> images;
      for (int threads : {1, 2, 3}) {
        set_num_threads(threads);
        RenderOptions o;
        o.strategy = strategy;
        o.ray_packets = packets;
        o.width = 45;
        o.height = 37;
        o.seed = 2;
        CpuRenderer r(scene.field, box_of(scene.vol), scene.mc, scene.tf, scene.cam, o);
        images.push_back(r.render(2));
      }
      set_num_threads(0);
      for (size_t k = 1; k < images.size(); ++k)
        for (size_t i = 0; i < images[0].pixels.size(); ++i) {
          const Vec4f &a = images[0].pixels[i], &b = images[k].pixels[i];
          ASSERT_TRUE(a.x == b.x && a.y == b.y && a.z == b.z && a.w == b.w)
              << render_strategy_name(strategy) << (packets ? " packets" : "") << " pixel " << i;
        }
    }
}

// The SIMD ray packets of in-shader grid ray marching (grid_packets.h) against the per-ray loop they
// replace, on every SIMD target this machine has: the same image bit for bit, and the same sample
// count, with adaptive and uniform steps, steps that are not one voxel (partial-step opacity),
// macro-cells on and off, an image size that is not a multiple of the tiles, early termination, and
// volumes too thin for packets (they fall back).
TEST(Strategies, RayPacketsGiveThePerRayImage) {
  struct Case {
    Int3 dims;
    float step, step_max, alpha;  // alpha < 0: the ramp preset, else a constant opacity (early stop)
    bool cells;
  };
  const Case cases[] = {{{40, 36, 32}, 1, 0, -1, true},   {{40, 36, 32}, 1, 1, -1, true},
                        {{40, 36, 32}, 0.7f, 0, -1, false}, {{33, 20, 27}, 1, 0, 0.5f, true},
                        {{2, 30, 30}, 1, 1, -1, true},      {{1, 30, 30}, 1, 0, -1, true}};
  for (const Case& c : cases) {
    Volume vol = synth(c.dims);
    GridField field(view_of(vol));
    TransferFunction tf = c.alpha < 0 ? tf_preset("ramp") : constant_tf(Vec3f{0.9f, 0.5f, 0.2f}, c.alpha);
    MacroCells mc = c.cells ? MacroCells(value_ranges_from_grid(view_of(vol), 8), box_of(vol))
                            : MacroCells::single(vol.dims, box_of(vol));
    mc.update(tf);
    Camera cam = orbit_camera(box_of(vol), 35, 25, 30);
    auto render = [&](bool packets, RenderStats* st) {
      RenderOptions o;
      o.strategy = RenderStrategy::InShader;
      o.ray_packets = packets;
      o.width = 37;
      o.height = 29;
      o.step = c.step;
      o.step_max = c.step_max;
      o.seed = 3;
      CpuRenderer r(field, box_of(vol), mc, tf, cam, o);
      return r.render(2, st);
    };
    RenderStats ref_stats;
    const Image ref = render(false, &ref_stats);
    for (int64_t t : hwy::SupportedAndGeneratedTargets()) {
      hwy::SetSupportedTargetsForTest(t);
      RenderStats st;
      const Image img = render(true, &st);
      EXPECT_EQ(st.field_samples, ref_stats.field_samples) << hwy::TargetName(t);
      double sum = 0;
      for (size_t i = 0; i < img.pixels.size(); ++i) {
        const Vec4f &a = img.pixels[i], &b = ref.pixels[i];
        ASSERT_TRUE(a.x == b.x && a.y == b.y && a.z == b.z && a.w == b.w)
            << hwy::TargetName(t) << " dims " << c.dims.x << " step " << c.step << " pixel " << i;
        sum += a.w;
      }
      EXPECT_GT(sum, 1.0) << "the image is not empty";
    }
    hwy::SetSupportedTargetsForTest(0);
  }
}

// A step's transmittance b^e (corrected_alpha's pow): against pow in double precision over the bases a
// table's opacities give (0, the smallest 1 - alpha above 0, up to 1) and step lengths up to 16 voxels;
// the packets' vector version (every SIMD target) equals it bit for bit.
TEST(Integrators, UnitPowIsPowAndThePacketsComputeItBitForBit) {
  std::vector<float> bs = {0.0f, 5.96e-8f, 1e-30f, 0.25f, 0.5f, 0.70710677f, 0.70710683f, 0.9999999f, 1.0f};
  std::vector<float> es = {0.0f, 1e-3f, 0.25f, 0.5f, 0.999f, 1.0f, 1.5f, 2.0f, 2.0000002f, 7.3f, 16.0f};
  Pcg32 rng(11, 3);
  for (int i = 0; i < 4000; ++i) {
    bs.push_back(rng.next_float());
    bs.push_back(std::exp2(-24.0f * rng.next_float()));  // 1 - alpha near 0 as well as near 1
  }
  for (int i = 0; i < 40; ++i) es.push_back(16.0f * rng.next_float());
  std::vector<float> b, e, want;
  double worst_rel = 0;  // where b^e >= 1/2: steps of opacity up to 1/2
  for (float x : bs)
    for (float y : es) {
      if (x == 0 && y == 0) continue;  // 0^0: a step has a length
      const float got = unit_pow(x, y);
      const double ref = std::pow(double(x), double(y)), err = std::fabs(double(got) - ref);
      EXPECT_LT(err, 1.5e-7) << x << "^" << y << " = " << ref << ", got " << got;
      if (ref >= 0.5) worst_rel = std::max(worst_rel, err / ref);
      b.push_back(x), e.push_back(y), want.push_back(got);
    }
  EXPECT_LT(worst_rel, 3e-7);
  EXPECT_EQ(unit_pow(-0.5f, 2.0f), 0.0f);
  EXPECT_EQ(unit_pow(std::nanf(""), 2.0f), 0.0f);
  EXPECT_EQ(corrected_alpha(0.0f, 0.37f), 0.0f);
  EXPECT_EQ(corrected_alpha(1.0f, 0.37f), 1.0f);
  for (float x : {-0.5f, std::nanf("")})
    for (float y : {0.5f, 2.0f}) b.push_back(x), e.push_back(y), want.push_back(unit_pow(x, y));
  std::string mismatch;  // the first, reported once every target has run and the dispatch is reset
  for (int64_t t : hwy::SupportedAndGeneratedTargets()) {
    hwy::SetSupportedTargetsForTest(t);
    std::vector<float> got(b.size());
    unit_pow_packets(b.data(), e.data(), got.data(), b.size());
    for (size_t i = 0; i < b.size() && mismatch.empty(); ++i)
      if (std::memcmp(&got[i], &want[i], 4) != 0) {
        std::ostringstream m;
        m << hwy::TargetName(t) << ": " << std::hexfloat << b[i] << "^" << e[i] << " = " << got[i] << ", scalar "
          << want[i];
        mismatch = m.str();
      }
  }
  hwy::SetSupportedTargetsForTest(0);
  EXPECT_EQ(mismatch, "");
}

TEST(Strategies, MacroCellsOnAndOffGiveTheSameRayMarchedImage) {
  Volume vol = blobs(Int3{48, 48, 48});
  GridField field(view_of(vol));
  TransferFunction tf = tf_preset("ramp");
  Camera cam = orbit_camera(box_of(vol), 20, 15, 30);
  auto render = [&](bool cells, float step_max, RenderStats* st) {
    MacroCells mc = cells ? MacroCells(value_ranges_from_grid(view_of(vol), 8), box_of(vol))
                          : MacroCells::single(vol.dims, box_of(vol));
    mc.update(tf);
    RenderOptions o;
    o.width = o.height = 64;
    o.step_max = step_max;
    CpuRenderer r(field, box_of(vol), mc, tf, cam, o);
    return r.render(4, st);
  };
  RenderStats s_on, s_off;
  // uniform steps: only the placement of steps at cell boundaries differs
  EXPECT_GT(image_psnr(render(true, 1, &s_on), render(false, 1, &s_off)), 40.0);
  EXPECT_LT(s_on.field_samples, s_off.field_samples) << "transparent cells are skipped";
  // adaptive steps: cells of low opacity take longer steps
  EXPECT_GT(image_psnr(render(true, 0, nullptr), render(false, 1, nullptr)), 30.0);
}

TEST(Strategies, TrainedModelRendersCloseToItsGrid) {
  Volume vol = synth(Int3{32, 32, 32});
  Json cfg = {{"encoding", {{"otype", "HashGrid"}, {"n_levels", 4}, {"n_features_per_level", 2},
                            {"log2_hashmap_size", 14}, {"base_resolution", 4}}},
              {"network", {{"otype", "FullyFusedMLP"}, {"n_neurons", 32}, {"n_hidden_layers", 2}}},
              {"loss", {{"otype", "L2"}}},
              {"optimizer", {{"otype", "Adam"}, {"learning_rate", 1e-2}}}};
  Network net(cfg);
  net.init_params(3);
  CpuTrainer trainer(net, std::make_shared<InCoreSampler>(vol), TrainOptions{16384, 3});
  trainer.enable_online_ranges(vol.dims, 8);
  for (int i = 0; i < 300; ++i) trainer.step();
  EvalResult ev = evaluate(net, vol, false);
  ASSERT_GT(ev.psnr, 24.0);
  GridField grid(view_of(vol));
  NetworkField neural(net, vol.dims);
  TransferFunction tf = tf_preset("ramp");
  MacroCells mc_grid(value_ranges_from_grid(view_of(vol), 8), box_of(vol)), mc_online(trainer.online_ranges(), box_of(vol));
  mc_grid.update(tf);
  mc_online.update(tf);
  Camera cam = orbit_camera(box_of(vol), 40, 25, 30);
  RenderOptions o;
  o.width = o.height = 64;
  Image ref = CpuRenderer(grid, box_of(vol), mc_grid, tf, cam, o).render(2);
  Image nn_grid = CpuRenderer(neural, box_of(vol), mc_grid, tf, cam, o).render(2);
  Image nn_online = CpuRenderer(neural, box_of(vol), mc_online, tf, cam, o).render(2);
  o.strategy = RenderStrategy::InShader;
  Image nn_inshader = CpuRenderer(neural, box_of(vol), mc_online, tf, cam, o).render(2);
  const double p_grid = image_psnr(nn_grid, ref), p_online = image_psnr(nn_online, ref);
  std::printf("model PSNR %.2f dB; image PSNR vs grid: %.2f dB (grid macro-cells), %.2f dB (online)\n", ev.psnr,
              p_grid, p_online);
  EXPECT_GT(p_grid, 30.0);
  EXPECT_GT(p_online, 30.0);
  EXPECT_GT(image_psnr(nn_inshader, nn_online), 50.0) << "the point evaluator agrees with batched inference";
  RecordProperty("image_psnr_grid_macrocells", std::to_string(p_grid));
  RecordProperty("image_psnr_online_macrocells", std::to_string(p_online));
}

TEST(CpuRenderer, RejectsBadOptions) {
  Volume vol = synth(Int3{8, 8, 8});
  GridField field(view_of(vol));
  TransferFunction tf = tf_preset("ramp");
  MacroCells mc = MacroCells::single(vol.dims, box_of(vol));
  Camera cam = orbit_camera(box_of(vol), 0, 0, 30);
  auto make = [&](auto&& edit) {
    RenderOptions o;
    edit(o);
    CpuRenderer r(field, box_of(vol), mc, tf, cam, o);
  };
  EXPECT_THROW(make([](RenderOptions& o) { o.width = 0; }), Error);
  EXPECT_THROW(make([](RenderOptions& o) { o.step = 0; }), Error);
  EXPECT_THROW(make([](RenderOptions& o) { o.step = NAN; }), Error);
  EXPECT_THROW(make([](RenderOptions& o) { o.step_max = 0.5f; }), Error);
  EXPECT_THROW(make([](RenderOptions& o) { o.samples_per_iteration = 0; }), Error);
  EXPECT_THROW(make([](RenderOptions& o) { o.density_scale = -1; }), Error);
  EXPECT_THROW(parse_render_mode("raytrace"), Error);
  EXPECT_THROW(parse_render_strategy("fast"), Error);
  EXPECT_THROW(parse_macrocell_mode("on"), Error);
}
