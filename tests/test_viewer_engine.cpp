// vnr::ViewerEngine (include/vnr/viewer.h) against independent references: its frames equal what
// vnr::Renderer renders for the same input, camera, TF, size and frame count; coarse frames while
// interacting, accumulation up to max_frames then idle; training (loss, PSNR estimate, pause, reset);
// slices equal the volume's voxels and the decoded network; time series; TF and scene files round
// trip through the renderer's readers; save_model's name rules and file; setter validation.
#include <gtest/gtest.h>
#include <chrono>
#include <cstring>
#include <functional>
#include <thread>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/model.h"
#include "vnr/renderer.h"
#include "vnr/render/transfer_function.h"
#include "vnr/train/session.h"
#include "vnr/viewer.h"
#include "vnr/api/viewer_impl.h"
#include "vnr/volume_writer.h"
#include "test_support.h"

using namespace vnr;
using namespace vnr::test;

namespace {

constexpr Int3 kDims{32, 32, 32};

// A small model config file (the engine trains it fast).
std::string small_config_file(const TmpDir& dir) {
  const std::string path = dir / "small.json";
  write_file_atomic(path, small_hash_config(14, 16, 1).dump());
  return path;
}

ViewerSetup volume_setup(const TmpDir& dir) {
  synth_volume("marschner-lobb", kDims, dir / "vol.json");
  ViewerSetup s;
  s.input = dir / "vol.json";
  s.config = small_config_file(dir);
  s.device = "cpu";
  s.batch = 4096;
  return s;
}

// A model trained a little (so it records online macro-cells), saved to dir/model.vnr.
std::string trained_model_file(const TmpDir& dir) {
  synth_volume("marschner-lobb", kDims, dir / "gt.json");
  const Volume vol = open_volume(dir / "gt.json");
  Model m = create_model(ModelConfig::from_json(small_hash_config(14, 16, 1)), vol, 7);
  auto session = make_training_session(m, vol, Device::Cpu, TrainOptions{4096, 7});
  session->run(30);
  session->finish();
  save_model(dir / "model.vnr", m);
  return dir / "model.vnr";
}

const ViewerImage* image_of(const ViewerFrame& f, const std::string& view) {
  for (const ViewerImage& img : f.images)
    if (img.view == view) return &img;
  return nullptr;
}

// Frames until one satisfies pred (null after timeout).
std::shared_ptr<const ViewerFrame> wait_for(const ViewerEngine& e, const std::function<bool(const ViewerFrame&)>& pred,
                                            double timeout = 30) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout);
  uint64_t last = 0;
  while (std::chrono::steady_clock::now() < end) {
    auto f = e.wait_frame(last, 0.5);
    if (!f) continue;
    last = f->id;
    if (pred(*f)) return f;
  }
  return nullptr;
}

bool wait_until(const std::function<bool()>& cond, double timeout = 30) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout);
  while (std::chrono::steady_clock::now() < end) {
    if (cond()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return cond();
}

// The reference: vnr::Renderer on the same input with the engine's camera, TF and size, `frames` frames.
// What vnr::Renderer draws for the same settings; with `cache`, from the model's warm brick cache.
std::vector<uint8_t> reference_rgba(const RenderInput& input, bool network, const ViewerState& st, int frames,
                                    bool cache = false) {
  std::unique_ptr<Renderer> r;
  if (network)
    r = std::make_unique<Renderer>(*input.model, Device::Cpu, input.volume ? &*input.volume : nullptr);
  else
    r = std::make_unique<Renderer>(*input.volume, Device::Cpu);
  r->set_scene(input.scene);
  r->set_camera(st.camera);
  r->set_transfer_function(to_transfer_function(st.tf));
  r->set_size(st.width, st.height);
  if (cache) r->choose_strategy("cache");
  r->warm_cache();
  for (int i = 0; i < frames; ++i) r->render_frame();
  return to_rgba8(r->image());
}

bool same_camera_for_test(const Camera& a, const Camera& b) {
  auto eq = [](Vec3f p, Vec3f q) { return p.x == q.x && p.y == q.y && p.z == q.z; };
  return eq(a.eye, b.eye) && eq(a.center, b.center) && eq(a.up, b.up) && a.fovy == b.fovy;
}

}  // namespace

// Strategy auto (the default) draws the network view from its brick cache, except while the network
// trains on the GPU and is drawn there; cache always; streaming and in-shader never.
TEST(ViewerEngine, AutoDrawsTheCacheButTheTrainingNetworkOnTheGpu) {
  ViewerRender r;
  EXPECT_EQ(r.settings.strategy, "auto");
  EXPECT_TRUE(viewer_wants_cache(r, false));
  EXPECT_FALSE(viewer_wants_cache(r, true));
  r.settings.strategy = "cache";
  EXPECT_TRUE(viewer_wants_cache(r, true));
  for (const char* direct : {"streaming", "inshader"}) {
    r.settings.strategy = direct;
    EXPECT_FALSE(viewer_wants_cache(r, false));
  }
}

TEST(ViewerEngine, DefaultTfReproducesThePresetTable) {
  TmpDir dir("viewer");
  ViewerEngine engine(volume_setup(dir));
  const TransferFunction mine = to_transfer_function(engine.state().tf);
  const TransferFunction preset = tf_preset("ramp");
  ASSERT_EQ(mine.table.size(), preset.table.size());
  for (size_t i = 0; i < preset.table.size(); ++i) {
    EXPECT_NEAR(mine.table[i].x, preset.table[i].x, 1e-6);
    EXPECT_NEAR(mine.table[i].y, preset.table[i].y, 1e-6);
    EXPECT_NEAR(mine.table[i].z, preset.table[i].z, 1e-6);
    EXPECT_NEAR(mine.table[i].w, preset.table[i].w, 1e-6);
  }
  EXPECT_EQ(mine.lo, preset.lo);
  EXPECT_EQ(mine.hi, preset.hi);
}

// The truth view of a volume input equals `vnr render INPUT` (Renderer over the volume) frame for frame.
TEST(ViewerEngine, TruthViewEqualsTheRenderer) {
  TmpDir dir("viewer");
  const ViewerSetup setup = volume_setup(dir);
  ViewerEngine engine(setup);
  const ViewerState st = engine.state();
  EXPECT_EQ(st.width, 512);
  EXPECT_EQ(st.view.layout, ViewLayout::SideBySide);
  EXPECT_EQ(st.render.settings.macrocells, "online");
  const RenderInput input = open_render_input(setup.input, "", {}, parse_precision("auto"));
  EXPECT_TRUE(same_camera_for_test(st.camera, orbit_camera(box_of(kDims), 0, 0, 30)));
  auto done = wait_for(engine, [](const ViewerFrame& f) { return f.refined && f.accumulated == 8; });
  ASSERT_TRUE(done);
  const ViewerImage* truth = image_of(*done, "truth");
  ASSERT_TRUE(truth);
  ASSERT_TRUE(image_of(*done, "network"));
  EXPECT_EQ(truth->width, 512);
  EXPECT_EQ(truth->height, 512);
  EXPECT_EQ(truth->rgba, reference_rgba(input, false, st, 8));
  // Complete: the engine goes idle (no new frame ids).
  EXPECT_FALSE(engine.wait_frame(done->id, 0.5));
}

// A model input: the network view equals Renderer(model) (online macro-cells of the model file).
TEST(ViewerEngine, NetworkViewEqualsTheRendererAndAccumulationStops) {
  TmpDir dir("viewer");
  ViewerSetup setup;
  setup.input = trained_model_file(dir);
  setup.device = "cpu";
  ViewerEngine engine(setup);
  EXPECT_FALSE(engine.info().can_train);
  EXPECT_EQ(engine.state().view.layout, ViewLayout::Network);
  EXPECT_EQ(engine.state().training.state, TrainingState::Unavailable);
  ViewerRender r = engine.state().render;
  EXPECT_EQ(r.settings.macrocells, "online");
  EXPECT_EQ(r.settings.strategy, "auto") << "the brick cache by default (on the CPU)";
  r.settings.strategy = "streaming";  // the network itself (the cache: NetworkCacheViewSharpensToTheWarmCachesImage)
  r.max_frames = 3;
  engine.set_viewport(160, 128);
  engine.set_render(r);
  auto done = wait_for(engine, [](const ViewerFrame& f) {
    return f.refined && f.accumulated == 3 && !f.images.empty() && f.images[0].width == 160;
  });
  ASSERT_TRUE(done);
  ASSERT_EQ(done->images.size(), 1u);
  const RenderInput input = open_render_input(setup.input, "", {}, parse_precision("auto"));
  EXPECT_EQ(done->images[0].rgba, reference_rgba(input, true, engine.state(), 3));
  EXPECT_FALSE(engine.wait_frame(done->id, 0.5));  // idle at max_frames

  // Interacting: one coarse frame of 1/coarse_scale size; then still: refined frames again.
  Camera cam = orbit_camera(box_of(kDims), 40, 20, 30);
  engine.set_camera(cam, true);
  auto coarse = wait_for(engine, [](const ViewerFrame& f) { return !f.refined; });
  ASSERT_TRUE(coarse);
  EXPECT_EQ(coarse->images[0].width, 80);
  EXPECT_EQ(coarse->images[0].height, 64);
  EXPECT_EQ(coarse->accumulated, 1);
  EXPECT_FALSE(engine.wait_frame(coarse->id, 0.3));  // one coarse frame per camera change
  engine.set_camera(cam, false);
  auto refined = wait_for(engine, [](const ViewerFrame& f) { return f.refined && f.accumulated == 3; });
  ASSERT_TRUE(refined);
  EXPECT_EQ(refined->images[0].width, 160);
  EXPECT_EQ(refined->images[0].rgba, reference_rgba(input, true, engine.state(), 3));
  const Image shot = engine.screenshot(10);
  EXPECT_EQ(to_rgba8(shot), refined->images[0].rgba);
}

TEST(ViewerEngine, NetworkCacheViewSharpensToTheWarmCachesImage) {
  TmpDir dir("viewer");
  ViewerSetup setup;
  setup.input = trained_model_file(dir);
  setup.device = "cpu";
  ViewerEngine engine(setup);
  ViewerRender r = engine.state().render;
  r.max_frames = 3;
  engine.set_viewport(160, 128);
  engine.set_render(r);
  // Accumulation completes once every brick the view reads is decoded: then the image is the one a
  // Renderer draws from its warm cache, and the engine goes idle.
  auto done = wait_for(engine, [](const ViewerFrame& f) {
    return f.refined && f.accumulated == 3 && f.cache_bricks > 0 && f.cache_pending == 0 && f.cache_stale == 0;
  });
  ASSERT_TRUE(done);
  const RenderInput input = open_render_input(setup.input, "", {}, parse_precision("auto"));
  const ViewerFrame* last = done.get();
  std::shared_ptr<const ViewerFrame> more;
  while ((more = engine.wait_frame(last->id, 1.0))) last = (done = more).get();  // until idle
  EXPECT_TRUE(last->refined);
  EXPECT_EQ(last->images[0].rgba, reference_rgba(input, true, engine.state(), 3, true));
  // Moving: full-resolution frames (no coarse ones) from the same cache.
  engine.set_camera(orbit_camera(box_of(kDims), 40, 20, 30), true);
  auto moving = wait_for(engine, [](const ViewerFrame& f) { return f.images.size() == 1 && f.accumulated >= 1; });
  ASSERT_TRUE(moving);
  EXPECT_EQ(moving->images[0].width, 160);
  EXPECT_GT(moving->cache_bricks, 0);
}

// vnr view --cache-dims/--cache-budget: the cache decodes the model at 256^3 (a 32^3 model has one
// brick of 32^3 a level there), so a close view reads more bricks than the model's own dims have, and
// a budget smaller than a brick is one clear error.
TEST(ViewerEngine, TheCacheDecodesAtTheDimsAndBudgetGiven) {
  TmpDir dir("viewer");
  ViewerSetup setup;
  setup.input = trained_model_file(dir);
  setup.device = "cpu";
  setup.cache_dims = Int3{256, 256, 256};
  setup.cache_budget = uint64_t(64) << 20;
  ViewerEngine engine(setup);
  engine.set_viewport(96, 96);
  engine.set_camera(orbit_camera(box_of(kDims), 30, 20, 30), false);
  auto done = wait_for(engine, [](const ViewerFrame& f) { return f.refined && f.cache_bricks > 8 && f.cache_pending == 0; });
  ASSERT_TRUE(done) << "the view reads bricks of the 256^3 levels";

  setup.cache_dims = Int3{0, 0, 0};
  setup.cache_budget = 1000;  // less than one brick of 33^3 floats
  EXPECT_HAS(error_of([&] { ViewerEngine small(setup); }), "holds no brick");
}

TEST(ViewerEngine, TrainingLossFallsPsnrRisesPauseAndReset) {
  TmpDir dir("viewer");
  ViewerEngine engine(volume_setup(dir));
  EXPECT_TRUE(engine.info().can_train);
  EXPECT_EQ(engine.state().training.state, TrainingState::Idle);
  engine.set_viewport(64, 64);
  engine.start_training();
  ASSERT_TRUE(wait_until([&] { return engine.psnr_history().size() >= 3 && engine.state().training.step >= 100; }));
  const std::vector<float> l = engine.losses(0);
  ASSERT_GE(l.size(), 100u);
  EXPECT_LT(l.back(), l.front());
  const auto psnr = engine.psnr_history();
  EXPECT_EQ(psnr.front()[0], 0);  // a probe before the first step
  EXPECT_GT(psnr.back()[1], psnr.front()[1] + 3);
  const ViewerTraining t = engine.state().training;
  EXPECT_GT(t.samples_per_second, 0);
  EXPECT_GT(t.seconds, 0);
  EXPECT_GT(t.psnr, 0);
  EXPECT_EQ(t.n_losses, size_t(engine.losses(0).size()));
  EXPECT_EQ(engine.losses(l.size()).size(), engine.state().training.n_losses - l.size());

  engine.pause_training();
  EXPECT_EQ(engine.state().training.state, TrainingState::Paused);
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  const int64_t paused_at = engine.state().training.step;
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_EQ(engine.state().training.step, paused_at);

  engine.reset_training(0.005);
  ViewerTraining r = engine.state().training;
  EXPECT_EQ(r.step, 0);
  EXPECT_EQ(r.state, TrainingState::Idle);
  EXPECT_EQ(r.n_losses, 0u);
  EXPECT_TRUE(engine.losses(0).empty());
  EXPECT_TRUE(engine.psnr_history().empty());
  ASSERT_TRUE(wait_until([&] { return std::abs(engine.state().training.learning_rate - 0.005) < 1e-9; }));
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  EXPECT_EQ(engine.state().training.step, 0);
  engine.start_training();
  ASSERT_TRUE(wait_until([&] { return engine.state().training.step >= 5; }));
  engine.stop();
  EXPECT_FALSE(engine.wait_frame(0, 0.1));
}

TEST(ViewerEngine, SaveModelNameRulesAndFile) {
  TmpDir dir("viewer");
  ViewerSetup setup = volume_setup(dir);
  {
    ViewerEngine no_dir(setup);
    EXPECT_HAS(error_of([&] { no_dir.save_model("m"); }), "save directory");
  }
  std::filesystem::create_directories(dir / "models");
  setup.save_dir = dir / "models";
  ViewerEngine engine(setup);
  for (const std::string bad : {"", "../x", "/abs", ".hidden", "a/b", "a b", "x\\y"})
    EXPECT_NE(error_of([&] { engine.save_model(bad); }), "") << bad;
  engine.set_viewport(32, 32);
  engine.start_training();
  ASSERT_TRUE(wait_until([&] { return engine.state().training.step >= 20; }));
  engine.pause_training();
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  const std::string path = engine.save_model("first");
  EXPECT_EQ(path, dir / "models/first.vnr");
  EXPECT_EQ(engine.save_model("again.vnr"), dir / "models/again.vnr");
  EXPECT_EQ(read_file(path), read_file(dir / "models/again.vnr"));  // paused: the same model
  const Model m = load_model(path);
  EXPECT_EQ(m.training["steps"].get<int64_t>(), engine.state().training.step);
  EXPECT_TRUE(m.dims == kDims);
  EXPECT_EQ(int64_t(m.net->n_params()), engine.info().n_params);
  EXPECT_TRUE(m.macrocells.has_value());
  // The saved model is the trained one: well above the untrained network's PSNR (the first probe).
  const EvalResult ev = evaluate_model(m, open_volume(setup.input), false);
  EXPECT_GT(ev.psnr, engine.psnr_history().front()[1] + 3);
}

// Slices: truth = the volume's voxels of the plane, network = the model decoded at voxel centres as
// `vnr decode` decodes it, difference = |network - truth| through the documented colour scale.
TEST(ViewerEngine, SlicesEqualVoxelsAndDecodedNetwork) {
  TmpDir dir("viewer");
  ViewerSetup setup;
  setup.input = trained_model_file(dir);
  setup.ground_truth = dir / "gt.json";
  setup.device = "cpu";
  ViewerEngine engine(setup);
  EXPECT_TRUE(engine.info().can_train);
  EXPECT_EQ(engine.state().view.layout, ViewLayout::SideBySide);
  engine.set_viewport(32, 32);
  const Volume vol = open_volume(setup.ground_truth);
  Model model = load_model(setup.input);
  model.net->set_inference_precision(parse_precision("auto"));
  const Volume decoded = ModelQuery(model, Device::Cpu).decode();
  const TransferFunction hot = tf_preset("hot");
  auto gray = [](float v) { return uint8_t(std::floor(255.0f * std::clamp(v, 0.0f, 1.0f) + 0.5f)); };
  for (int axis = 0; axis < 3; ++axis) {
    ViewSettings v = engine.state().view;
    v.slice = true;
    v.slice_axis = axis;
    v.slice_position = 0.3f;
    engine.set_view(v);
    const uint64_t version = engine.state().version;
    auto f = wait_for(engine, [&](const ViewerFrame& fr) { return fr.state_version >= version && image_of(fr, "slice_truth"); });
    ASSERT_TRUE(f);
    const ViewerImage* truth = image_of(*f, "slice_truth");
    const ViewerImage* net = image_of(*f, "slice_network");
    const ViewerImage* diff = image_of(*f, "slice_difference");
    ASSERT_TRUE(truth && net && diff);
    EXPECT_EQ(truth->width, 32);
    EXPECT_EQ(truth->height, 32);
    const int index = int(0.3f * 32);  // 9
    for (int row = 0; row < 32; ++row)
      for (int col = 0; col < 32; ++col) {
        int64_t p[3];
        const int u = axis == 0 ? 1 : 0, w = axis == 2 ? 1 : 2;
        p[axis] = index, p[u] = col, p[w] = 31 - row;  // row 0 at the top: the plane's second axis points up
        const size_t voxel = size_t(p[0] + 32 * (p[1] + 32 * p[2]));
        const size_t px = 4 * size_t(row * 32 + col);
        ASSERT_EQ(truth->rgba[px], gray(vol.data[voxel])) << axis << " " << row << " " << col;
        ASSERT_EQ(net->rgba[px], gray(decoded.data[voxel])) << axis << " " << row << " " << col;
        const Vec4f c = tf_lookup(view_of(hot), std::fabs(decoded.data[voxel] - vol.data[voxel]) / 0.1f);
        ASSERT_EQ(diff->rgba[px], gray(c.x));
        ASSERT_EQ(diff->rgba[px + 1], gray(c.y));
      }
  }
}

TEST(ViewerEngine, TimestepsSwitchTheTruthAndContinuousTrainingAdvances) {
  TmpDir dir("viewer");
  synth_series("marschner-lobb", kDims, 3, dir / "series.json");
  ViewerSetup setup;
  setup.input = dir / "series.json";
  setup.config = small_config_file(dir);
  setup.device = "cpu";
  setup.batch = 4096;
  ViewerEngine engine(setup);
  EXPECT_EQ(engine.info().n_timesteps, 3);
  engine.set_viewport(48, 48);
  ViewSettings v = engine.state().view;
  v.layout = ViewLayout::Truth;
  engine.set_view(v);
  engine.set_timestep(2);
  EXPECT_EQ(engine.state().training.timestep, 2);
  const uint64_t version = engine.state().version;
  auto f = wait_for(engine, [&](const ViewerFrame& fr) { return fr.state_version >= version && fr.accumulated == 8; });
  ASSERT_TRUE(f);
  ASSERT_EQ(f->images.size(), 1u);
  EXPECT_EQ(f->images[0].view, "truth");
  VolumeOpenOptions o;
  o.raw.timestep = 2;
  RenderInput t2;
  t2.volume = open_volume(setup.input, o);
  EXPECT_EQ(f->images[0].rgba, reference_rgba(t2, false, engine.state(), 8));
  o.raw.timestep = 0;
  RenderInput t0;
  t0.volume = open_volume(setup.input, o);
  EXPECT_NE(f->images[0].rgba, reference_rgba(t0, false, engine.state(), 8));

  EXPECT_HAS(error_of([&] { engine.set_timestep(3); }), "timestep 3");
  engine.set_continuous(true, 20);
  engine.start_training();
  // 2 -> 0 -> 1 every 20 steps.
  ASSERT_TRUE(wait_until([&] { return engine.state().training.timestep == 0; }));
  const int64_t s0 = engine.state().training.step;
  ASSERT_TRUE(wait_until([&] { return engine.state().training.timestep == 1; }));
  const int64_t s1 = engine.state().training.step;
  EXPECT_GE(s0, 20);
  EXPECT_GE(s1, 40);
  engine.pause_training();
  const auto losses = engine.losses(0);
  EXPECT_GE(losses.size(), 40u);
}

// An error on the engine thread (a timestep whose file went away) lands in the state and pauses
// training; the thread keeps serving.
TEST(ViewerEngine, EngineThreadErrorsGoToTheState) {
  TmpDir dir("viewer");
  synth_series("marschner-lobb", {16, 16, 16}, 2, dir / "list.json", 1, true);
  ViewerSetup setup;
  setup.input = dir / "list.json";
  setup.config = small_config_file(dir);
  setup.batch = 4096;
  setup.train = true;
  ViewerEngine engine(setup);
  std::filesystem::remove(synth_series_output_files(dir / "list.json", 2, true)[1]);
  EXPECT_EQ(engine.state().training.state, TrainingState::Running);
  engine.set_viewport(32, 32);
  engine.set_timestep(1);
  ASSERT_TRUE(wait_until([&] { return engine.state().error_count > 0; }));
  const ViewerState st = engine.state();
  EXPECT_HAS(st.last_error, "t0001");
  EXPECT_EQ(st.training.state, TrainingState::Paused);
  engine.set_camera(orbit_camera(box_of(Int3{16, 16, 16}), 90, 0, 30), false);
  EXPECT_TRUE(wait_for(engine, [](const ViewerFrame& f) { return f.refined; }, 10));
}

TEST(ViewerEngine, TfAndSceneJsonRoundTrip) {
  TmpDir dir("viewer");
  ViewerEngine engine(volume_setup(dir));
  ViewerTf tf;
  tf.colormap = "custom";
  tf.custom_colors = {{0.1f, 0.2f, 0.9f}, {0.9f, 0.9f, 0.1f}, {1.0f, 0.3f, 0.2f}};
  tf.opacity = {{0.0f, 0.0f}, {0.4f, 0.05f}, {0.7f, 0.6f}, {1.0f, 0.2f}};
  tf.lo = 0.1f;
  tf.hi = 0.9f;
  engine.set_tf(tf);
  const TransferFunction mine = to_transfer_function(tf);
  write_file_atomic(dir / "tf.json", engine.tf_json());
  const TransferFunction back = load_transfer_function(dir / "tf.json");
  ASSERT_EQ(back.table.size(), mine.table.size());
  EXPECT_EQ(back.lo, 0);  // the window baked in
  for (size_t i = 0; i < back.table.size(); ++i) {
    const Vec4f want = tf_lookup(view_of(mine), float(double(i) / double(back.table.size() - 1)));
    ASSERT_NEAR(back.table[i].x, want.x, 1e-6) << i;
    ASSERT_NEAR(back.table[i].z, want.z, 1e-6) << i;
    ASSERT_NEAR(back.table[i].w, want.w, 1e-6) << i;
  }
  // The default window: the table itself.
  tf.lo = 0;
  tf.hi = 1;
  engine.set_tf(tf);
  const Camera cam = orbit_camera(box_of(kDims), 30, 25, 40);
  engine.set_camera(cam, false);
  write_file_atomic(dir / "scene.json", engine.scene_json());
  const Scene scene = load_scene(dir / "scene.json");
  ASSERT_TRUE(scene.camera && scene.tf);
  EXPECT_NEAR(scene.camera->eye.x, cam.eye.x, 1e-4);
  EXPECT_NEAR(scene.camera->eye.z, cam.eye.z, 1e-4);
  EXPECT_NEAR(scene.camera->center.y, cam.center.y, 1e-5);
  EXPECT_EQ(scene.camera->fovy, cam.fovy);
  const TransferFunction table = to_transfer_function(tf);
  ASSERT_EQ(scene.tf->table.size(), table.table.size());
  for (size_t i = 0; i < table.table.size(); ++i) {
    ASSERT_EQ(scene.tf->table[i].y, table.table[i].y) << i;
    ASSERT_EQ(scene.tf->table[i].w, table.table[i].w) << i;
  }

  // load_tf_json: its own TF file back (custom colours, few opacity points) ...
  engine.load_tf_json(read_file(dir / "scene.json"));
  const ViewerTf loaded = engine.state().tf;
  EXPECT_EQ(loaded.colormap, "custom");
  EXPECT_LE(loaded.opacity.size(), 64u);
  const TransferFunction again = to_transfer_function(loaded);
  for (size_t i = 0; i < table.table.size(); ++i) {
    ASSERT_NEAR(again.table[i].x, table.table[i].x, 2e-3) << i;
    ASSERT_NEAR(again.table[i].w, table.table[i].w, 2e-3) << i;
  }
  // ... an instantvnr TF written by hand (a preset's colours: the colormap becomes that preset) ...
  const Json hand = {{"transferFunction",
                      {{"resolution", 1024},
                       {"colorControls",
                        {{{"position", 0.0}, {"color", {{"r", 0.0}, {"g", 0.0}, {"b", 0.0}}}},
                         {{"position", 1.0}, {"color", {{"r", 1.0}, {"g", 1.0}, {"b", 1.0}}}}}},
                       {"opacityControl",
                        {{{"position", {{"x", 0.0}, {"y", 0.0}}}}, {{"position", {{"x", 0.5}, {"y", 0.3}}}},
                         {{"position", {{"x", 1.0}, {"y", 0.9}}}}}}}}};
  engine.load_tf_json(hand.dump());
  const TransferFunction want = tf_from_json(hand, "hand");
  const TransferFunction got = to_transfer_function(engine.state().tf);
  for (int i = 0; i <= 100; ++i) {
    const Vec4f a = tf_lookup(view_of(want), float(i) / 100), b = tf_lookup(view_of(got), float(i) / 100);
    EXPECT_NEAR(a.x, b.x, 2e-3) << i;
    EXPECT_NEAR(a.w, b.w, 2e-3) << i;
  }
  // ... and a whole vnr scene sets the camera too; bad text changes nothing.
  const Json vnr_scene = {{"camera", {{"eye", {100, 20, 10}}, {"center", {16, 16, 16}}}}, {"transfer_function", "hot"}};
  engine.load_tf_json(vnr_scene.dump());
  EXPECT_EQ(engine.state().camera.eye.x, 100);
  EXPECT_EQ(engine.state().tf.colormap, "hot");
  const uint64_t version = engine.state().version;
  EXPECT_HAS(error_of([&] { engine.load_tf_json("{\"colors\": 3"); }), "transfer function");
  EXPECT_HAS(error_of([&] { engine.load_tf_json("{\"transfer_function\": \"/etc/passwd\"}"); }), "names a file");
  EXPECT_EQ(engine.state().version, version);
}

// An instantvnr scene as the input brings its camera and TF; the truth view equals `vnr render SCENE`.
TEST(ViewerEngine, SceneInputUsesItsCameraAndTf) {
  TmpDir dir("viewer");
  synth_volume("marschner-lobb", kDims, dir / "vol.json");
  const Camera cam = orbit_camera(box_of(kDims), 60, 30, 35);
  Json scene = scene_to_instantvnr_json(cam, tf_preset("cool-warm"));
  scene["dataSource"] = {{{"fileName", "vol.raw"},
                          {"dimensions", {{"x", 32}, {"y", 32}, {"z", 32}}},
                          {"type", "FLOAT"},
                          {"endian", "LITTLE_ENDIAN"},
                          {"format", "REGULAR_GRID_RAW_BINARY"},
                          {"offset", 0}}};
  write_file_atomic(dir / "scene.json", scene.dump());
  ViewerSetup setup;
  setup.input = dir / "scene.json";
  setup.config = small_config_file(dir);
  ViewerEngine engine(setup);
  const RenderInput input = open_render_input(setup.input, "", {}, Precision::FP32);
  ASSERT_TRUE(input.scene.camera);
  EXPECT_TRUE(same_camera_for_test(engine.state().camera, *input.scene.camera));
  EXPECT_EQ(engine.state().tf.colormap, "cool-warm");  // the file's table has the preset's colours
  auto f = wait_for(engine, [](const ViewerFrame& fr) { return fr.accumulated == 8 && image_of(fr, "truth"); });
  ASSERT_TRUE(f);
  RenderInput same;
  same.volume = open_volume(setup.input);
  same.scene = input.scene;
  EXPECT_EQ(image_of(*f, "truth")->rgba, reference_rgba(same, false, engine.state(), 8));
}

TEST(ViewerEngine, BadSetterValuesThrowAndChangeNothing) {
  TmpDir dir("viewer");
  ViewerSetup setup;
  setup.input = trained_model_file(dir);
  ViewerEngine engine(setup);
  const uint64_t version = engine.state().version;
  EXPECT_HAS(error_of([&] { engine.set_viewport(8, 100); }), "width 8");
  EXPECT_HAS(error_of([&] { engine.set_viewport(100, 5000); }), "height 5000");
  ViewSettings v;
  v.layout = ViewLayout::Truth;
  EXPECT_HAS(error_of([&] { engine.set_view(v); }), "needs a volume");
  v.layout = ViewLayout::Network;
  v.slice_axis = 3;
  EXPECT_HAS(error_of([&] { engine.set_view(v); }), "slice axis 3");
  v.slice_axis = 0;
  v.slice_position = 1.5f;
  EXPECT_HAS(error_of([&] { engine.set_view(v); }), "slice position 1.5");
  ViewerTf tf = engine.state().tf;
  tf.colormap = "rainbowz";
  EXPECT_HAS(error_of([&] { engine.set_tf(tf); }), "rainbowz");
  tf = engine.state().tf;
  tf.opacity = {{0.5f, 0.1f}, {0.2f, 0.3f}};
  EXPECT_HAS(error_of([&] { engine.set_tf(tf); }), "sorted");
  tf = engine.state().tf;
  tf.lo = 0.7f;
  tf.hi = 0.2f;
  EXPECT_HAS(error_of([&] { engine.set_tf(tf); }), "[0.7, 0.2]");
  ViewerRender r = engine.state().render;
  r.settings.step = -1;
  EXPECT_HAS(error_of([&] { engine.set_render(r); }), "step -1");
  r = engine.state().render;
  r.settings.mode = "xray";
  EXPECT_HAS(error_of([&] { engine.set_render(r); }), "xray");
  r = engine.state().render;
  r.settings.macrocells = "grid";
  EXPECT_HAS(error_of([&] { engine.set_render(r); }), "grid");
  r = engine.state().render;
  r.coarse_scale = 0;
  EXPECT_HAS(error_of([&] { engine.set_render(r); }), "coarse_scale 0");
  Camera c = engine.state().camera;
  c.center = c.eye;
  EXPECT_NE(error_of([&] { engine.set_camera(c, false); }), "");
  c = engine.state().camera;
  c.fovy = 0;
  EXPECT_HAS(error_of([&] { engine.set_camera(c, false); }), "fovy 0");
  EXPECT_HAS(error_of([&] { engine.start_training(); }), "ground truth");
  EXPECT_HAS(error_of([&] { engine.set_training_budget(0.0005); }), "budget 0.0005");
  EXPECT_HAS(error_of([&] { engine.set_timestep(1); }), "timestep 1");
  EXPECT_HAS(error_of([&] { engine.histogram(0); }), "bins 0");
  EXPECT_HAS(error_of([&] { engine.save_model("x"); }), "save directory");
  EXPECT_EQ(engine.state().version, version);

  ViewerSetup bad;
  bad.input = dir / "missing.json";
  EXPECT_HAS(error_of([&] { ViewerEngine e(bad); }), "missing.json");
}

TEST(ViewerEngine, HistogramCountsTheVolume) {
  TmpDir dir("viewer");
  ViewerEngine engine(volume_setup(dir));
  const Volume vol = open_volume(dir / "vol.json");
  std::vector<uint32_t> want(4, 0);
  for (float v : vol.data) ++want[std::min(3, int(v * 4))];
  EXPECT_EQ(engine.histogram(4), want);
  const auto h = engine.histogram();
  EXPECT_EQ(h.size(), 256u);
  uint64_t total = 0;
  for (uint32_t c : h) total += c;
  EXPECT_EQ(total, kDims.count());
}
