// The online training-and-rendering loop (vnr/online): frames equal those of a freshly built renderer
// over the same network and macro-cells (bit for bit, both strategies), the online macro-cells are
// exactly the value ranges of the training samples drawn so far, loss history and frame timing, image
// quality rising with training, accumulation restarting on every change; training previews
// (TrainPreview) and `vnr train --preview-*` end to end.
#include <gtest/gtest.h>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/json.h"
#include "vnr/core/value_range_grid.h"
#include "vnr/online.h"
#include "vnr/fields/fields.h"
#include "vnr/render/macrocell.h"
#include "vnr/render/renderer.h"
#include "vnr/train/session.h"
#include "vnr/render/image.h"
#include "vnr/train/sampler.h"
#include "vnr/train/session.h"
#include "vnr/train/trainer.h"
#include "vnr/volume_writer.h"
#include "test_support.h"

using namespace vnr;
using namespace vnr::test;

namespace {

Json small_config() { return small_hash_config(14, 32, 2); }

bool same_pixels(const Image& a, const Image& b) {
  return a.width == b.width && a.height == b.height &&
         std::memcmp(a.pixels.data(), b.pixels.data(), a.pixels.size() * sizeof(Vec4f)) == 0;
}

Model small_model(Int3 dims, uint32_t seed) {
  Model m;
  m.net = std::make_unique<Network>(small_config());
  m.net->init_params(seed);
  m.dims = dims;
  return m;
}

// A session over a CpuTrainer without online ranges (the loop's refusals).
std::unique_ptr<TrainingSession> cpu_session(Model& m, const Volume& vol, int64_t batch, uint32_t seed) {
  return std::make_unique<TrainingSession>(
      m, std::make_unique<CpuTrainer>(*m.net, std::make_shared<InCoreSampler>(vol), TrainOptions{batch, seed}));
}

// A model, the training session with online ranges that trains it, its CPU trainer and the volume it learns.
struct Training {
  Volume vol;
  Model model;
  std::unique_ptr<TrainingSession> session;
  CpuTrainer& trainer;
  Training(Int3 dims, int64_t batch, int cell_size, uint32_t seed = 3)
      : vol(synth(dims)), model(small_model(dims, seed)), session(cpu_session(model, vol, batch, seed)),
        trainer(static_cast<CpuTrainer&>(session->trainer())) {
    trainer.enable_online_ranges(vol.dims, cell_size);
  }
};

RenderOptions small_options(RenderMode mode = RenderMode::RayMarch,
                            RenderStrategy strategy = RenderStrategy::Streaming) {
  RenderOptions o;
  o.width = 48;
  o.height = 40;
  o.mode = mode;
  o.strategy = strategy;
  return o;
}

// A renderer built from scratch over the network's current parameters and the trainer's ranges.
Image fresh_render(CpuTrainer& trainer, Int3 dims, const TransferFunction& tf, const Camera& cam,
                   const RenderOptions& o, int frames) {
  NetworkField field(trainer.network(), dims);
  MacroCells mc(trainer.online_ranges(), box_of(dims));
  mc.update(tf);
  return CpuRenderer(field, box_of(dims), mc, tf, cam, o).render(frames);
}

bool same_table(const TransferFunction& a, const TransferFunction& b) {
  return a.table.size() == b.table.size() &&
         std::memcmp(a.table.data(), b.table.data(), a.table.size() * sizeof(Vec4f)) == 0;
}

}  // namespace

TEST(OnlineLoop, FramesMatchAFreshRendererBitForBit) {
  Training s(Int3{24, 20, 28}, 4096, 8);
  const TransferFunction tf = tf_preset("ramp");
  const Camera cam = orbit_camera(box_of(s.vol.dims), 30, 20, 30);
  for (RenderStrategy strategy : {RenderStrategy::Streaming, RenderStrategy::InShader}) {
    SCOPED_TRACE(render_strategy_name(strategy));
    const RenderOptions o = small_options(RenderMode::RayMarch, strategy);
    OnlineLoop loop(*s.session, s.vol.dims, tf, cam, o);
    loop.train(10);
    const Image a = loop.render_frame();
    EXPECT_EQ(loop.accumulated_frames(), 1);
    EXPECT_TRUE(same_pixels(a, fresh_render(s.trainer, s.vol.dims, tf, cam, o, 1)));
    // More training: the loop sees the new parameters (the in-shader evaluator's weight copy is rebuilt)
    // and the new ranges.
    loop.train(10);
    const Image b = loop.render_frame();
    EXPECT_EQ(loop.accumulated_frames(), 1) << "a training step restarts accumulation";
    EXPECT_FALSE(same_pixels(a, b)) << "the frame after more training shows the trained model";
    EXPECT_TRUE(same_pixels(b, fresh_render(s.trainer, s.vol.dims, tf, cam, o, 1)));
    // Without training, frames accumulate exactly as CpuRenderer::render(n) does.
    loop.render_frame();
    const Image c = loop.render_frame();
    EXPECT_EQ(loop.accumulated_frames(), 3);
    EXPECT_TRUE(same_pixels(c, fresh_render(s.trainer, s.vol.dims, tf, cam, o, 3)));
  }
  // Path tracing (random numbers per frame number) with accumulation.
  const RenderOptions o = small_options(RenderMode::PathTrace);
  OnlineLoop loop(*s.session, s.vol.dims, tf, cam, o);
  loop.train(3);
  for (int i = 0; i < 4; ++i) loop.render_frame();
  EXPECT_TRUE(same_pixels(loop.image(), fresh_render(s.trainer, s.vol.dims, tf, cam, o, 4)));
}

TEST(OnlineLoop, MacroCellsAreTheValueRangesOfTheTrainingSamples) {
  // Small batches over many small cells, so that after k steps some cells are still untouched.
  const int64_t batch = 1024;
  const int k = 3;
  Training s(Int3{64, 64, 64}, batch, 4);  // 16^3 cells
  const TransferFunction tf = tf_preset("ramp");
  OnlineLoop loop(*s.session, s.vol.dims, tf, orbit_camera(box_of(s.vol.dims), 0, 0, 30), small_options());
  loop.train(k);
  loop.render_frame();
  ASSERT_NE(loop.macrocells(), nullptr);
  const ValueRangeGrid& online = loop.macrocells()->ranges();

  // The same samples, drawn again: the trainer's chunks of (seed, step, chunk).
  const int C = kChunk;
  InCoreSampler sampler(s.vol);
  ValueRangeGrid ref(s.vol.dims, 4);
  std::vector<float> x(C), y(C), z(C), v(C);
  std::vector<uint8_t> hit(size_t(ref.count()), 0);
  for (int step = 0; step < k; ++step) {
    sampler.begin_step(uint64_t(step));
    for (int64_t c = 0; c < batch / C; ++c) {
      sampler.sample(s.trainer.options().seed, uint64_t(step), uint64_t(c), C, x.data(), y.data(), z.data(), v.data());
      ref.add_samples(x.data(), y.data(), z.data(), v.data(), C);
      for (int i = 0; i < C; ++i) {  // the cell the sample fell in
        int64_t cx = std::min<int64_t>(int64_t(x[i] * 64) / 4, 15), cy = std::min<int64_t>(int64_t(y[i] * 64) / 4, 15),
                cz = std::min<int64_t>(int64_t(z[i] * 64) / 4, 15);
        hit[size_t(cx + 16 * (cy + 16 * cz))] = 1;
      }
    }
  }
  ASSERT_EQ(online.count(), ref.count());
  int64_t empty = 0, sampled = 0;
  for (int64_t c = 0; c < ref.count(); ++c) {
    EXPECT_EQ(online.lo[c], ref.lo[c]) << c;
    EXPECT_EQ(online.hi[c], ref.hi[c]) << c;
    if (hit[c]) {
      ++sampled;
      EXPECT_FALSE(online.empty(c)) << "a cell where a training sample fell has a range";
    }
    empty += online.empty(c);
  }
  EXPECT_GT(empty, 0) << "cells no sample reached stay empty (transparent)";
  EXPECT_GT(sampled, ref.count() / 4);
  // ...and the max opacities are recomputed for the transfer function.
  MacroCells mc(ref, box_of(s.vol.dims));
  mc.update(tf);
  EXPECT_EQ(loop.macrocells()->max_opacity(), mc.max_opacity());
  for (int64_t c = 0; c < ref.count(); ++c)
    if (online.empty(c)) {
      EXPECT_EQ(loop.macrocells()->max_opacity()[c], 0.0f);
    }
  // A new transfer function: the next frame's macro-cells carry its opacities.
  const TransferFunction tf2 = tf_preset("cool-warm");
  loop.set_transfer_function(tf2);
  loop.render_frame();
  mc.update(tf2);
  EXPECT_EQ(loop.macrocells()->max_opacity(), mc.max_opacity());
}

TEST(OnlineLoop, LossHistoryAndFrameTiming) {
  Training s(Int3{16, 16, 16}, 2048, 8);
  OnlineLoop loop(*s.session, s.vol.dims, tf_preset("ramp"), orbit_camera(box_of(s.vol.dims), 0, 0, 30),
                  small_options());
  loop.train(5);
  EXPECT_EQ(loop.loss_history().size(), 5u);
  std::vector<uint64_t> steps;
  int64_t done = loop.run(10, 4, [&](const Image& img, const OnlineFrame& f) {
    EXPECT_EQ(img.width, 48);
    EXPECT_EQ(f.accumulated, 1);
    EXPECT_GT(f.train_seconds, 0.0);
    EXPECT_GT(f.render_seconds, 0.0);
    EXPECT_GE(f.update_seconds, 0.0);
    EXPECT_EQ(f.loss, loop.loss_history().back());
    steps.push_back(f.step);
    return true;
  });
  EXPECT_EQ(done, 10);
  EXPECT_EQ(steps, (std::vector<uint64_t>{9, 13, 15}));
  EXPECT_EQ(loop.loss_history().size(), 15u);
  EXPECT_EQ(loop.frames().size(), 3u);
  for (float l : loop.loss_history()) EXPECT_TRUE(std::isfinite(l));
  // The callback can stop the loop.
  int calls = 0;
  EXPECT_EQ(loop.run(100, 2, [&](const Image&, const OnlineFrame&) { return ++calls < 2; }), 4);
  EXPECT_EQ(loop.loss_history().size(), 19u);
  EXPECT_THROW(loop.run(10, 0, nullptr), Error);
  EXPECT_THROW(loop.train(-1), Error);
}

TEST(OnlineLoop, ImageQualityImprovesAsTrainingProceeds) {
  Training s(Int3{32, 32, 32}, 16384, 8);
  const TransferFunction tf = tf_preset("ramp");
  const Camera cam = orbit_camera(box_of(s.vol.dims), 40, 25, 30);
  const RenderOptions o = small_options();
  GridField grid(view_of(s.vol));
  MacroCells mc_grid(value_ranges_from_grid(view_of(s.vol), 8), box_of(s.vol.dims));
  mc_grid.update(tf);
  const Image truth = CpuRenderer(grid, box_of(s.vol.dims), mc_grid, tf, cam, o).render(1);
  OnlineLoop loop(*s.session, s.vol.dims, tf, cam, o);
  std::vector<double> psnr;
  for (int steps : {0, 10, 140}) {
    loop.train(steps);
    psnr.push_back(compare_images(loop.render_frame(), truth).psnr);
  }
  std::printf("online frame PSNR vs the grid after 0, 10, 150 steps: %.2f, %.2f, %.2f dB\n", psnr[0], psnr[1],
              psnr[2]);
  EXPECT_LT(psnr[0], psnr[1]);
  EXPECT_LT(psnr[1], psnr[2]);
  EXPECT_GT(psnr[2], 28.0);
}

TEST(OnlineLoop, AccumulationRestartsOnEveryChange) {
  Training s(Int3{24, 24, 24}, 4096, 8);
  const TransferFunction tf = tf_preset("ramp");
  const Camera cam1 = orbit_camera(box_of(s.vol.dims), 0, 10, 30), cam2 = orbit_camera(box_of(s.vol.dims), 90, 10, 30);
  const RenderOptions o = small_options(RenderMode::PathTrace);
  OnlineLoop loop(*s.session, s.vol.dims, tf, cam1, o);
  loop.train(20);
  for (int i = 0; i < 3; ++i) loop.render_frame();
  EXPECT_EQ(loop.accumulated_frames(), 3);
  const Image three = loop.image();
  loop.set_camera(cam2);
  loop.render_frame();
  EXPECT_EQ(loop.accumulated_frames(), 1) << "a camera change restarts accumulation";
  EXPECT_TRUE(same_pixels(loop.image(), fresh_render(s.trainer, s.vol.dims, tf, cam2, o, 1)));
  loop.render_frame();
  EXPECT_EQ(loop.accumulated_frames(), 2);
  EXPECT_TRUE(same_pixels(loop.image(), fresh_render(s.trainer, s.vol.dims, tf, cam2, o, 2)));
  loop.set_camera(cam1);
  for (int i = 0; i < 3; ++i) loop.render_frame();
  EXPECT_TRUE(same_pixels(loop.image(), three)) << "back at the first view: the same accumulated image";
  const TransferFunction tf2 = tf_preset("hot");
  loop.set_transfer_function(tf2);
  loop.render_frame();
  EXPECT_EQ(loop.accumulated_frames(), 1) << "a transfer-function change restarts accumulation";
  EXPECT_TRUE(same_pixels(loop.image(), fresh_render(s.trainer, s.vol.dims, tf2, cam1, o, 1)));
  RenderOptions o2 = small_options(RenderMode::Shadow);
  loop.set_options(o2);
  loop.render_frame();
  EXPECT_EQ(loop.accumulated_frames(), 1);
  EXPECT_TRUE(same_pixels(loop.image(), fresh_render(s.trainer, s.vol.dims, tf2, cam1, o2, 1)));
  loop.render_frame();
  EXPECT_EQ(loop.accumulated_frames(), 2);
  s.trainer.step();  // a step taken outside the loop is noticed too
  loop.render_frame();
  EXPECT_EQ(loop.accumulated_frames(), 1);
  EXPECT_TRUE(same_pixels(loop.image(), fresh_render(s.trainer, s.vol.dims, tf2, cam1, o2, 1)));
}

TEST(OnlineLoop, RejectsWhatCannotWork) {
  Volume vol = synth(Int3{16, 16, 16});
  Model model = small_model(vol.dims, 1);
  std::unique_ptr<TrainingSession> plain_session = cpu_session(model, vol, 1024, 1);
  TrainingSession& plain = *plain_session;
  const TransferFunction tf = tf_preset("ramp");
  const Camera cam = orbit_camera(box_of(vol.dims), 0, 0, 30);
  EXPECT_THROW(OnlineLoop(plain, vol.dims, tf, cam, small_options()), Error) << "no online ranges recorded";
  EXPECT_THROW(OnlineLoop(plain, vol.dims, tf, cam, small_options(), MacroCellMode::Grid), Error);
  {
    OnlineLoop off(plain, vol.dims, tf, cam, small_options(), MacroCellMode::Off);  // one macro-cell: works
    off.train(2);
    off.render_frame();
    EXPECT_EQ(off.macrocells()->ranges().count(), 1);
  }
  plain.trainer().enable_online_ranges(vol.dims, 8);
  EXPECT_THROW(OnlineLoop(plain, Int3{16, 16, 17}, tf, cam, small_options()), Error) << "dims differ";
}

TEST(TrainPreview, WritesPngsEveryNSteps) {
  Training s(Int3{24, 24, 24}, 2048, 8);
  TmpDir tmp;
  PreviewOptions o;
  o.every = 4;
  o.dir = tmp / "preview/nested/dir";  // created with its parents
  o.width = 48;
  o.height = 32;
  TrainPreview preview(o, *s.session, s.vol.dims);
  for (int64_t step = 1; step <= 10; ++step) {
    s.trainer.step();
    double t = preview.after_step(step);
    if (step % 4 == 0)
      EXPECT_GT(t, 0.0) << step;
    else
      EXPECT_EQ(t, 0.0) << step;
  }
  EXPECT_EQ(preview.after_step(8), 0.0) << "a step is written once";
  // Previews infer in bf16 where the CPU has it, then hand the network back in its own precision.
  EXPECT_EQ(s.trainer.network().inference_precision(), Precision::FP32);
  EXPECT_GT(preview.finish(10), 0.0) << "the final step, not a multiple of 4";
  EXPECT_EQ(preview.finish(10), 0.0);
  EXPECT_EQ(preview.frames_written(), 3);
  EXPECT_EQ(preview.last_path(), o.dir + "/step_000010.png");
  std::vector<std::string> names;
  for (auto& e : std::filesystem::directory_iterator(o.dir)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"step_000004.png", "step_000008.png", "step_000010.png"}))
      << "no temporaries or probe files left";
  Image a = read_image(o.dir + "/step_000004.png"), b = read_image(o.dir + "/step_000008.png"),
        c = read_image(o.dir + "/step_000010.png");
  EXPECT_EQ(a.width, 48);
  EXPECT_EQ(a.height, 32);
  EXPECT_FALSE(same_pixels(a, b)) << "the model changed between previews";
  // The last file is the loop's last frame, quantised to 8 bits.
  const Image& last = preview.loop().image();
  ASSERT_EQ(c.pixels.size(), last.pixels.size());
  double max_err = 0;
  for (size_t i = 0; i < c.pixels.size(); ++i)
    max_err = std::max({max_err, std::abs(double(c.pixels[i].x) - std::clamp(double(last.pixels[i].x), 0.0, 1.0)),
                        std::abs(double(c.pixels[i].y) - std::clamp(double(last.pixels[i].y), 0.0, 1.0)),
                        std::abs(double(c.pixels[i].z) - std::clamp(double(last.pixels[i].z), 0.0, 1.0))});
  EXPECT_LE(max_err, 0.5 / 255 + 1e-6);
  double lit = 0;
  for (const Vec4f& p : c.pixels) lit += p.x + p.y + p.z;
  EXPECT_GT(lit, 0) << "the preview shows something";
  EXPECT_EQ(preview_path("d", 1234567), "d/step_1234567.png");
}

TEST(TrainPreview, RejectsBadOptionsBeforeTraining) {
  TmpDir tmp;
  const std::string base = tmp.str();
  { std::ofstream(base + "/file") << "x"; }
  PreviewOptions o;
  o.dir = base + "/ok";
  o.every = 0;
  EXPECT_THROW(check_preview_options(o), Error);
  o.every = 5;
  o.dir = "";
  EXPECT_THROW(check_preview_options(o), Error);
  o.dir = base + "/file";  // exists, not a directory
  EXPECT_THROW(check_preview_options(o), Error);
  o.dir = base + "/file/sub";  // cannot be created
  try {
    check_preview_options(o);
    ADD_FAILURE() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(o.dir), std::string::npos) << e.what();
  }
  o.dir = base + "/ok";
  o.width = 0;
  EXPECT_THROW(check_preview_options(o), Error);
  o.width = 16;
  EXPECT_NO_THROW(check_preview_options(o));
  EXPECT_TRUE(std::filesystem::is_directory(o.dir));
  EXPECT_TRUE(std::filesystem::is_empty(o.dir)) << "the probe is removed";
}

// `vnr train --preview-*` end to end: the PNGs appear with the right names and size, the report
// leaves preview time out of training time, and every bad flag is one error line before training.
TEST(TrainPreview, CommandLine) {
  TmpDir tmp;
  const std::string vol = tmp / "ml.json", model = tmp / "ml.vnr", prev = tmp / "prev";
  synth_volume("marschner-lobb", Int3{24, 24, 24}, vol);
  Result r = run("train " + vol + " -o " + model + " --config small --batch 4096 --steps 6 --preview-every 3 " +
                 "--preview-dir " + prev + " --preview-size 40x30 --preview-mode shadow --preview-tf hot -q " +
                 "--report " + (tmp / "r.json"));
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("previews: 2 PNG(s)"), std::string::npos) << r.out;
  for (const char* f : {"/step_000003.png", "/step_000006.png"}) {
    Image im = read_image(prev + f);
    EXPECT_EQ(im.width, 40);
    EXPECT_EQ(im.height, 30);
  }
  Json rep = parse_json_file(tmp / "r.json");
  EXPECT_GT(rep["preview_seconds"].get<double>(), 0.0);
  const std::string base = "train " + vol + " -o " + model + " --config small --steps 2 ";
  expect_error(base + "--preview-every 10", "--preview-dir");
  expect_error(base + "--preview-dir " + prev, "--preview-every");
  expect_error(base + "--preview-mode shadow", "--preview-every");
  expect_error(base + "--preview-every 0 --preview-dir " + prev, "positive");
  expect_error(base + "--preview-every 2 --preview-dir " + prev + " --preview-size 64", "--preview-size");
  expect_error(base + "--preview-every 2 --preview-dir " + prev + " --preview-mode raytrace", "--preview-mode");
  expect_error(base + "--preview-every 2 --preview-dir " + prev + " --preview-tf nosuch", "--preview-tf");
  expect_error(base + "--preview-every 2 --preview-dir " + vol + "/sub", "preview directory");
}
