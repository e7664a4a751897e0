// The public objects (include/vnr/): Volume opening and arrays, Model create/save/load, queries and
// decodes, and the Renderer facade against CpuRenderer built by hand.
#include <gtest/gtest.h>
#include <cmath>
#include <cstring>
#include <fstream>
#include <fmt/format.h>
#include "render_support.h"
#include "test_support.h"
#include "vnr/render_cuda/gpu_renderer.h"
#include "vnr/vnr.h"
#include "vnr/train/model_io.h"

using namespace vnr;
using namespace vnr::test;

namespace {

const Int3 kDims{12, 10, 8};

// Original-unit values with a non-trivial range, x fastest.
std::vector<float> original_values(Int3 d) {
  std::vector<float> v(d.count());
  for (int64_t i = 0; i < int64_t(v.size()); ++i) v[size_t(i)] = 100.0f + 37.5f * std::sin(0.37f * float(i));
  return v;
}

// A float32 raw file and its JSON sidecar; returns the sidecar's path.
std::string write_sidecar_volume(const TmpDir& dir, Int3 d, const std::vector<float>& values) {
  std::ofstream(dir / "v.raw", std::ios::binary)
      .write(reinterpret_cast<const char*>(values.data()), std::streamsize(values.size() * sizeof(float)));
  const Json side = {{"file", "v.raw"}, {"dims", {d.x, d.y, d.z}}, {"dtype", "float32"}};
  std::ofstream(dir / "v.json") << side.dump();
  return dir / "v.json";
}

Model tiny_model(const Volume& vol, uint32_t seed = 7) {
  return create_model(ModelConfig::from_json(preset_config("tiny")), vol, seed);
}

bool same_pixels(const Image& a, const Image& b) {
  return a.width == b.width && a.height == b.height &&
         std::memcmp(a.pixels.data(), b.pixels.data(), a.pixels.size() * sizeof(Vec4f)) == 0;
}

}  // namespace

TEST(ApiVolume, OpensASidecarLikeLoadVolume) {
  TmpDir dir;
  const std::string path = write_sidecar_volume(dir, kDims, original_values(kDims));
  Volume a = open_volume(path);
  Volume b = load_volume(describe_volume(path));
  EXPECT_TRUE(a.dims == kDims);
  EXPECT_EQ(a.source_dtype, DType::Float32);
  EXPECT_EQ(a.lo, b.lo);
  EXPECT_EQ(a.hi, b.hi);
  ASSERT_EQ(a.data.size(), b.data.size());
  EXPECT_EQ(std::memcmp(a.data.data(), b.data.data(), a.data.size() * sizeof(float)), 0);
  EXPECT_EQ(volume_value(a, 0.3f, 0.6f, 0.2f), grid_lookup(view_of(b), 0.3f, 0.6f, 0.2f));

  // Load options: a range override.
  VolumeOpenOptions o;
  o.raw.range_lo = 50.0;
  o.raw.range_hi = 150.0;
  Volume r = open_volume(path, o);
  EXPECT_EQ(r.lo, 50.0);
  EXPECT_EQ(r.hi, 150.0);
  EXPECT_EQ(describe_volume_file(path, o).range_lo, 50.0);
}

TEST(ApiVolume, FromAnArrayEqualsTheSameValuesFromAFile) {
  TmpDir dir;
  std::vector<float> values = original_values(kDims);
  const std::string path = write_sidecar_volume(dir, kDims, values);
  Volume file = open_volume(path);
  Volume array = volume_from_array(values.data(), kDims);
  EXPECT_EQ(array.lo, file.lo);
  EXPECT_EQ(array.hi, file.hi);
  EXPECT_EQ(std::memcmp(array.data.data(), file.data.data(), file.data.size() * sizeof(float)), 0);

  Volume ranged = volume_from_array(values.data(), kDims, 0.0, 200.0);
  EXPECT_EQ(ranged.lo, 0.0);
  EXPECT_EQ(ranged.hi, 200.0);
  EXPECT_NEAR(ranged.data[3], (values[3] - 0.0) / 200.0, 1e-6);

  values[5] = std::nanf("");
  expect_error([&] { volume_from_array(values.data(), kDims); }, {"NaN"});
  Volume zeroed = volume_from_array(values.data(), kDims, {}, {}, NonFinitePolicy::Zero);
  EXPECT_EQ(zeroed.data[5], 0.0f);
  expect_error([&] { volume_from_array(values.data(), Int3{0, 1, 1}); }, {"dims"});
}

TEST(ApiModel, CreateSaveLoadRoundTrip) {
  TmpDir dir;
  Volume vol = volume_from_array(original_values(kDims).data(), kDims);
  Model m = tiny_model(vol);
  EXPECT_TRUE(m.dims == kDims);
  EXPECT_EQ(m.lo, vol.lo);
  EXPECT_EQ(m.hi, vol.hi);
  EXPECT_EQ(source_bytes(m), kDims.count() * 4);
  EXPECT_DOUBLE_EQ(compression_ratio(m), double(kDims.count() * 4) / double(m.net->n_params() * 2));
  for (const char* name : {"m.vnr", "m.bson"}) {
    save_model(dir / name, m);
    Model l = load_model(dir / name);
    EXPECT_EQ(l.net->n_params(), m.net->n_params()) << name;
    EXPECT_EQ(l.net->params_half(), m.net->params_half()) << name;
    EXPECT_TRUE(l.dims == m.dims) << name;
  }
  Model l = load_model(dir / "m.vnr");
  EXPECT_EQ(l.lo, m.lo);
  EXPECT_EQ(l.hi, m.hi);
  EXPECT_EQ(l.source_dtype, m.source_dtype);
  // The configuration and inference arithmetic through the model (front ends do not reach the Network).
  EXPECT_EQ(model_config(l).network.n_neurons, m.net->config().network.n_neurons);
  set_inference_precision(l, Precision::FP32);
  EXPECT_EQ(inference_precision(l), Precision::FP32);
  EXPECT_EQ(l.net->inference_precision(), Precision::FP32);
  expect_error([] { inference_precision(Model{}); }, {"no network"});
}

// check_unit_points names the first point outside [0, 1]^3 (or not finite), however the work was split.
TEST(ApiModel, UnitPointCheckNamesTheFirstBadPoint) {
  std::vector<float> xyz(3 * 300000, 0.5f);
  check_unit_points(xyz.data(), 300000);
  for (const auto& [at, value] : {std::pair{3 * 250000 + 2, 1.5f}, std::pair{3 * 7 + 1, std::nanf("")}}) {
    xyz[size_t(at)] = value;
    std::string message;
    try {
      check_unit_points(xyz.data(), 300000, 10);
    } catch (const Error& e) {
      message = e.what();
    }
    EXPECT_NE(message.find(fmt::format("point {} has {}", 10 + at / 3, "xyz"[at % 3])), std::string::npos) << message;
  }
}

TEST(ApiModel, QueriesEqualTheDecoderAndSlabsEqualTheFullDecode) {
  Volume vol = volume_from_array(original_values(kDims).data(), kDims);
  Model m = tiny_model(vol);
  ModelQuery q(m, Device::Cpu);
  const Int3 d{9, 7, 6};  // any resolution
  std::vector<int64_t> idx = {0, 5, 17, 100, 200, int64_t(d.count()) - 1};
  std::vector<float> xyz(3 * idx.size()), got(idx.size()), want(idx.size());
  for (size_t i = 0; i < idx.size(); ++i) voxel_centre(d, idx[i], &xyz[3 * i], &xyz[3 * i + 1], &xyz[3 * i + 2]);
  q.points(xyz.data(), int64_t(idx.size()), got.data());
  Decoder(*m.net, Device::Cpu).voxels(d, idx.data(), int64_t(idx.size()), want.data());
  for (size_t i = 0; i < idx.size(); ++i) EXPECT_EQ(got[i], want[i]) << i;

  std::vector<float> orig(idx.size());
  q.points(xyz.data(), int64_t(idx.size()), orig.data(), ValueUnits::Original);
  for (size_t i = 0; i < idx.size(); ++i) EXPECT_EQ(orig[i], to_original_units(m, want[i]));

  Volume full = q.decode(d);
  EXPECT_TRUE(full.dims == d);
  EXPECT_EQ(full.lo, m.lo);
  std::vector<float> slab(size_t(d.x * d.y * 3));
  q.slab(d, 2, 5, slab.data());
  EXPECT_EQ(std::memcmp(slab.data(), full.data.data() + d.x * d.y * 2, slab.size() * sizeof(float)), 0);
  std::vector<float> all(d.count());
  decode_slices(*m.net, d, 0, d.z, all.data());
  EXPECT_EQ(std::memcmp(all.data(), full.data.data(), all.size() * sizeof(float)), 0);
  expect_error([&] { q.slab(d, 4, 9, slab.data()); }, {"slab"});

  EvalResult a = evaluate_model(m, vol, true), b = evaluate(*m.net, vol, true);
  EXPECT_EQ(a.psnr, b.psnr);
  EXPECT_EQ(a.ssim, b.ssim);
  EXPECT_EQ(a.max_abs_error, b.max_abs_error);
}

namespace {
RenderOptions small_options(RenderMode mode = RenderMode::RayMarch) {
  RenderOptions o;
  o.width = 24;
  o.height = 20;
  o.mode = mode;
  o.seed = 3;
  return o;
}
}  // namespace

TEST(ApiRenderer, RendersWhatAHandBuiltCpuRendererRenders) {
  GridScene s;
  for (RenderMode mode : {RenderMode::RayMarch, RenderMode::PathTrace}) {
    const RenderOptions o = small_options(mode);
    Renderer r(s.vol, Device::Cpu);
    r.set_options(o);
    r.set_camera(s.cam);
    r.set_transfer_function(s.tf);
    r.set_macrocells(MacroCellMode::Grid, 8);
    EXPECT_EQ(r.macrocell_mode(), MacroCellMode::Grid);
    CpuRenderer hand(s.field, box_of(s.vol), s.mc, s.tf, s.cam, o);
    r.render_frame();
    EXPECT_EQ(r.frames(), 1);
    EXPECT_TRUE(same_pixels(r.image(), hand.render(1))) << render_mode_name(mode);
    // Accumulation: N frames equal CpuRenderer::render(N).
    for (int i = 1; i < 4; ++i) r.render_frame();
    EXPECT_EQ(r.frames(), 4);
    EXPECT_TRUE(same_pixels(r.image(), hand.render(4))) << render_mode_name(mode);
  }
}

TEST(ApiRenderer, AnyChangeRestartsAndGivesAFreshRenderersImage) {
  GridScene s;
  Renderer r(s.vol, Device::Cpu);
  r.set_options(small_options());
  r.set_camera(s.cam);
  r.set_macrocells(MacroCellMode::Grid, 8);
  for (int i = 0; i < 3; ++i) r.render_frame();

  auto fresh = [&](const Camera& cam, const TransferFunction& tf, RenderMode mode, int frames) {
    Renderer f(s.vol, Device::Cpu);
    f.set_options(small_options(mode));
    f.set_camera(cam);
    f.set_transfer_function(tf);
    f.set_macrocells(MacroCellMode::Grid, 8);
    for (int i = 0; i < frames; ++i) f.render_frame();
    return f.image();
  };
  const Camera cam2 = orbit_camera(box_of(s.vol), 120, -10, 30);
  r.set_camera(cam2);
  EXPECT_EQ(r.frames(), 0);
  r.render_frame();
  r.render_frame();
  EXPECT_TRUE(same_pixels(r.image(), fresh(cam2, s.tf, RenderMode::RayMarch, 2)));

  const TransferFunction tf2 = tf_preset(tf_preset_names().back());
  r.set_transfer_function(tf2);
  EXPECT_EQ(r.frames(), 0);
  r.render_frame();
  EXPECT_TRUE(same_pixels(r.image(), fresh(cam2, tf2, RenderMode::RayMarch, 1)));

  r.set_mode(RenderMode::Shadow);
  r.render_frame();
  r.render_frame();
  EXPECT_TRUE(same_pixels(r.image(), fresh(cam2, tf2, RenderMode::Shadow, 2)));
}

// Macro-cells switched off and back (as bench render's cells do) give the grid mode's image again, and
// a new cell size its own.
TEST(ApiRenderer, MacroCellsSwitchedOffAndBackRenderAsBefore) {
  GridScene s;
  Renderer r(s.vol, Device::Cpu);
  r.set_options(small_options());
  r.set_camera(s.cam);
  r.set_macrocells(MacroCellMode::Grid, 8);
  const Image grid = r.render_frame();
  r.set_macrocells(MacroCellMode::Off);
  r.render_frame();
  r.set_macrocells(MacroCellMode::Grid, 8);
  EXPECT_TRUE(same_pixels(r.render_frame(), grid));
  CpuRenderer hand(s.field, box_of(s.vol), s.mc, s.tf, s.cam, small_options());
  EXPECT_TRUE(same_pixels(grid, hand.render(1)));

  r.set_macrocells(MacroCellMode::Grid, 4);
  Renderer fresh(s.vol, Device::Cpu);
  fresh.set_options(small_options());
  fresh.set_camera(s.cam);
  fresh.set_macrocells(MacroCellMode::Grid, 4);
  EXPECT_TRUE(same_pixels(r.render_frame(), fresh.render_frame()));
  EXPECT_EQ(r.macrocell_mode(), MacroCellMode::Grid);
}

// vnr bench render's table through the library: every mode x strategy, macro-cells off then on, in
// order; a bad strategy fails before anything is timed; the renderer keeps its options.
TEST(ApiRenderer, RenderBenchmarkTimesEveryCellInOrder) {
  GridScene s;
  Renderer r(s.vol, Device::Cpu);
  r.set_options(small_options());
  const RenderOrbit orbit{1, 0, 20, 30, 8};
  int calls = 0;
  const std::vector<RenderBenchRow> rows =
      render_benchmark(r, {RenderMode::RayMarch, RenderMode::Shadow}, {"inshader", "streaming"}, MacroCellMode::Grid,
                       orbit, BrickCacheSettings{}, [&](const RenderBenchRow&) { ++calls; });
  ASSERT_EQ(rows.size(), 8u);
  EXPECT_EQ(calls, 8);
  for (size_t i = 0; i < rows.size(); ++i) {
    EXPECT_EQ(rows[i].mode, i < 4 ? RenderMode::RayMarch : RenderMode::Shadow);
    EXPECT_EQ(rows[i].strategy, (i / 2) % 2 ? "streaming" : "inshader");
    EXPECT_EQ(rows[i].macrocells, i % 2 ? MacroCellMode::Grid : MacroCellMode::Off);
    EXPECT_GT(rows[i].fps, 0);
    EXPECT_GT(rows[i].field_samples_per_second, 0);
  }
  EXPECT_EQ(r.options().mode, small_options().mode);
  EXPECT_EQ(r.options().strategy, small_options().strategy);
  expect_error([&] { render_benchmark(r, {RenderMode::RayMarch}, {"sideways"}, MacroCellMode::Grid, orbit, {}); },
               {"sideways"});
  const std::vector<TuneKRow> ks = tune_samples_per_iteration(r, {1, 4}, MacroCellMode::Grid, orbit);
  ASSERT_EQ(ks.size(), 2u);
  EXPECT_EQ(ks[1].k, 4);
  EXPECT_GT(ks[0].samples_per_frame, 0);
}

TEST(ApiRenderer, AnEmptyRenderInputFailsWithOneError) {
  expect_error([] { Renderer r(RenderInput{}, Device::Cpu); }, {"neither a model nor a volume"});
}

TEST(ApiRenderer, RendersAModelAndChecksItsMacroCells) {
  GridScene s;
  Model m = tiny_model(s.vol);
  Renderer r(m, Device::Cpu, &s.vol);
  EXPECT_EQ(r.macrocell_mode(), MacroCellMode::Grid);  // no online ranges, a ground truth at hand
  EXPECT_STREQ(r.field().kind(), "network");
  r.set_options(small_options());
  r.set_camera(s.cam);
  r.set_macrocells(MacroCellMode::Grid, 8);
  NetworkField field(*m.net, m.dims);
  CpuRenderer hand(field, box_of(s.vol), s.mc, s.tf, s.cam, small_options());
  r.render_frame();
  r.render_frame();
  EXPECT_TRUE(same_pixels(r.image(), hand.render(2)));

  TmpDir dir;
  r.save(dir / "a.pfm");
  Image back = read_image(dir / "a.pfm");  // PFM keeps RGB exactly (alpha reads back as 1)
  ASSERT_EQ(back.pixels.size(), r.image().pixels.size());
  for (size_t i = 0; i < back.pixels.size(); ++i) {
    EXPECT_EQ(back.pixels[i].x, r.image().pixels[i].x);
    EXPECT_EQ(back.pixels[i].y, r.image().pixels[i].y);
    EXPECT_EQ(back.pixels[i].z, r.image().pixels[i].z);
  }

  Renderer no_truth(m, Device::Cpu);
  EXPECT_EQ(no_truth.macrocell_mode(), MacroCellMode::Off);
  no_truth.set_macrocells(MacroCellMode::Grid);
  expect_error([&] { no_truth.render_frame(); }, {"--macrocells grid needs the ground-truth volume"});
  no_truth.set_macrocells(MacroCellMode::Online);
  expect_error([&] { no_truth.prepare(); }, {"--macrocells online needs a model trained by vnr"});
}

TEST(ApiRenderer, OpensRenderInputsFromFiles) {
  TmpDir dir;
  const std::string vol_path = write_sidecar_volume(dir, kDims, original_values(kDims));
  Volume vol = open_volume(vol_path);
  Model m = tiny_model(vol);
  save_model(dir / "m.vnr", m);
  EXPECT_TRUE(is_model_path(dir / "m.vnr"));
  EXPECT_FALSE(is_model_path(vol_path));
  RenderInput in = open_render_input(dir / "m.vnr", vol_path, {}, Precision::FP32);
  ASSERT_TRUE(in.model && in.volume);
  EXPECT_EQ(in.description, "model m.vnr");
  RenderInput v = open_render_input(vol_path, "", {}, Precision::FP32);
  EXPECT_FALSE(v.model);
  expect_error([&] { open_render_input(vol_path, vol_path, {}, Precision::FP32); }, {"--volume is only for model"});
  EXPECT_EQ(choose_render_device("cpu", &*in.model), Device::Cpu);
  Renderer r(in, Device::Cpu);
  EXPECT_STREQ(r.field().kind(), "network");
  EXPECT_GT(field_query_rate(r, 0.01), 0);
}

TEST(ApiModel, PlansFileEvaluationsByTheMemoryBudget) {
  VolumeDesc desc;
  desc.dims = Int3{64, 32, 100};
  const uint64_t full = desc.dims.count() * 8;
  EXPECT_EQ(plan_file_evaluation(desc, 0, true, full).method, EvalMethod::Full);
  EXPECT_EQ(plan_file_evaluation(desc, 1000, true, full).method, EvalMethod::Sampled);
  FileEvalPlan p = plan_file_evaluation(desc, 0, false, full - 1);
  EXPECT_EQ(p.method, EvalMethod::Streamed);
  EXPECT_EQ(p.full_bytes, full);
  // Without SSIM two slab arrays of floats: (full - 1) / (2 * 4 * slice) slices.
  EXPECT_EQ(p.slab_slices, int64_t((full - 1) / (2 * 4 * 64 * 32)));
  FileEvalPlan with_ssim = plan_file_evaluation(desc, 0, true, full - 1);
  EXPECT_EQ(with_ssim.slab_slices, int64_t((full - 1) / (3 * 4 * 64 * 32)) - 6);
  EXPECT_EQ(plan_file_evaluation(desc, 0, true, uint64_t(0)).slab_slices, 1);  // at least one slice
  EXPECT_STREQ(eval_method_name(EvalMethod::Streamed), "streamed");
}

// The GPU paths of the objects: the same results as the backends built by hand (skipped without a GPU).
TEST(ApiGpu, QueriesAndRendersLikeTheBackendsBuiltByHand) {
  if (cuda::devices().empty()) GTEST_SKIP() << "no CUDA device: " << cuda::no_device_reason();
  GridScene s;
  Model m = tiny_model(s.vol);
  ModelQuery q(m, Device::Cuda);
  const Int3 d{9, 7, 6};
  std::vector<float> full(d.count()), want(d.count());
  q.slab(d, 0, d.z, full.data());
  Decoder(*m.net, Device::Cuda).slices(d, 0, d.z, want.data());
  EXPECT_EQ(full, want);
  std::vector<int64_t> idx = {0, 7, 100, int64_t(d.count()) - 1};
  std::vector<float> xyz(3 * idx.size()), got(idx.size());
  for (size_t i = 0; i < idx.size(); ++i) voxel_centre(d, idx[i], &xyz[3 * i], &xyz[3 * i + 1], &xyz[3 * i + 2]);
  q.points(xyz.data(), int64_t(idx.size()), got.data());
  for (size_t i = 0; i < idx.size(); ++i) EXPECT_EQ(got[i], full[size_t(idx[i])]) << i;

  Renderer r(s.vol, Device::Cuda);
  r.set_options(small_options());
  r.set_camera(s.cam);
  r.set_macrocells(MacroCellMode::Grid, 8);
  r.render_frame();
  r.render_frame();
  std::unique_ptr<FrameRenderer> hand =
      make_renderer(Device::Cuda, s.field, box_of(s.vol), s.mc, s.tf, s.cam, small_options());
  EXPECT_TRUE(same_pixels(r.image(), hand->render(2)));
}

// The noise estimate against the closed form: frames whose pixels alternate between 0 and 1 (grey)
// have, after n frames, a sample variance of k(n-k)/(n(n-1)) (k ones) and so a standard error of the
// mean of sqrt(k(n-k)/(n^2(n-1))) in every pixel.
TEST(ApiRenderer, NoiseEstimateMatchesTheClosedForm) {
  Image acc(3, 2), frame(3, 2);
  std::vector<float> m2;
  int ones = 0;
  for (int n = 1; n <= 9; ++n) {
    const float v = n % 3 == 0 ? 1.0f : 0.0f;
    ones += n % 3 == 0;
    for (Vec4f& p : frame.pixels) p = Vec4f{v, v, v, 1};
    accumulate_frame(acc, frame, n - 1, &m2);
    if (n < 2) {
      EXPECT_TRUE(std::isinf(accumulated_noise(m2, n)));
      continue;
    }
    const double expect = std::sqrt(double(ones) * (n - ones) / (double(n) * n * (n - 1)));
    EXPECT_NEAR(accumulated_noise(m2, n), expect, 1e-6) << n;
    EXPECT_NEAR(acc.pixels[4].x, double(ones) / n, 1e-6);
  }
}

// render_until_converged stops at the first frame whose noise reaches the target (not before
// min_frames), or at max_frames; the image is the same as that many render_frame calls, and the noise
// of path tracing falls about as 1/sqrt(frames).
TEST(ApiRenderer, RendersUntilTheNoiseReachesTheTarget) {
  GridScene s;
  auto renderer = [&] {
    auto r = std::make_unique<Renderer>(s.vol, Device::Cpu);
    r->set_options(small_options(RenderMode::PathTrace));
    r->set_camera(s.cam);
    r->set_macrocells(MacroCellMode::Grid, 8);
    return r;
  };
  auto r = renderer();
  std::vector<double> noise;
  const int frames = r->render_until_converged({0.0, 4, 24}, nullptr, [&](int f, double n) {
    EXPECT_EQ(f, int(noise.size()) + 1);
    noise.push_back(n);
  });
  ASSERT_EQ(frames, 24);  // a target of 0 is never reached
  EXPECT_NEAR(noise[23] / noise[5], std::sqrt(6.0 / 24.0), 0.25 * std::sqrt(6.0 / 24.0));
  const double target = noise[11];  // reached first at frame 12, or earlier when the estimate dipped
  int first = 4;
  while (noise[first - 1] > target) ++first;
  auto again = renderer();
  EXPECT_EQ(again->render_until_converged({target, 4, 24}), first);
  auto hand = renderer();
  for (int i = 0; i < first; ++i) hand->render_frame();
  EXPECT_TRUE(same_pixels(again->image(), hand->image()));
  EXPECT_THROW(again->render_until_converged({-1, 4, 24}), Error);
  EXPECT_THROW(again->render_until_converged({0.01, 5, 4}), Error);
}

// --strategy auto: the measured faster strategy per field kind, device and mode (docs/benchmarks.md),
// and a renderer asks for the one of its own field, device and mode.
TEST(ApiRenderer, AutomaticStrategyFollowsTheMeasuredTable) {
  using S = RenderStrategy;
  using M = RenderMode;
  const struct {
    const char* kind;
    bool gpu;
    M mode;
    S want;
  } table[] = {{"grid", false, M::RayMarch, S::InShader},     {"grid", false, M::Shadow, S::Streaming},
               {"grid", false, M::PathTrace, S::InShader},    {"network", false, M::RayMarch, S::Streaming},
               {"network", false, M::Shadow, S::Streaming},   {"network", false, M::PathTrace, S::Streaming},
               {"grid", true, M::Shadow, S::InShader},        {"network", true, M::RayMarch, S::InShader},
               {"network", true, M::Shadow, S::Streaming},    {"network", true, M::PathTrace, S::InShader}};
  for (const auto& t : table)
    EXPECT_EQ(fastest_render_strategy(t.kind, t.gpu, t.mode), t.want) << t.kind << t.gpu << render_mode_name(t.mode);
  GridScene s;
  Renderer volume(s.vol, Device::Cpu);
  volume.set_mode(RenderMode::RayMarch);
  EXPECT_EQ(volume.automatic_strategy(), S::InShader);
  volume.set_mode(RenderMode::Shadow);
  EXPECT_EQ(volume.automatic_strategy(), S::Streaming);
  Model m = tiny_model(s.vol);
  Renderer network(m, Device::Cpu);
  EXPECT_EQ(network.automatic_strategy(), S::Streaming);
}
