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
#include "vnr/core/error.h"
#include "vnr/core/fileio.h"
#include "vnr/model.h"
#include "vnr/renderer.h"
#include "vnr/train/session.h"
#include "vnr/viewer.h"
#include "vnr/volume/writer.h"
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
  session->record();
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
std::vector<uint8_t> reference_rgba(const RenderInput& input, bool network, const ViewerState& st, int frames) {
  std::unique_ptr<Renderer> r;
  if (network)
    r = std::make_unique<Renderer>(*input.model, Device::Cpu, input.volume ? &*input.volume : nullptr);
  else
    r = std::make_unique<Renderer>(*input.volume, Device::Cpu);
  r->set_scene(input.scene);
  r->set_camera(st.camera);
  r->set_transfer_function(to_transfer_function(st.tf));
  r->set_size(st.width, st.height);
  for (int i = 0; i < frames; ++i) r->render_frame();
  return to_rgba8(r->image());
}

bool same_camera_for_test(const Camera& a, const Camera& b) {
  auto eq = [](Vec3f p, Vec3f q) { return p.x == q.x && p.y == q.y && p.z == q.z; };
  return eq(a.eye, b.eye) && eq(a.center, b.center) && eq(a.up, b.up) && a.fovy == b.fovy;
}

std::string error_of(const std::function<void()>& fn) {
  try {
    fn();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

}  // namespace

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
  EXPECT_EQ(st.render.macrocells, MacroCellMode::Online);
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
  EXPECT_EQ(r.macrocells, MacroCellMode::Online);
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
