// evaluate_model_file (include/vnr/model.h): the whole `vnr eval` as one library call. In memory it
// gives evaluate()'s numbers; the plan still picks streamed slabs over the memory budget and sampled
// voxels when asked; the range, notes, progress and file sizes come back with the result.
#include <gtest/gtest.h>
#include <cmath>
#include <fstream>
#include <map>
#include <string>
#include <vector>
#include "test_support.h"
#include "vnr/fileio.h"
#include "vnr/trainer.h"
#include "vnr/vnr.h"
#include "vnr/train/session.h"

using namespace vnr;
using namespace vnr::test;

namespace {

const Int3 kDims{20, 18, 11};

// A model of the synthetic volume at dir/v.json, trained briefly so the errors are not trivial, saved
// as dir/m.vnr (a .vnr records the value range it was trained with).
Model trained_model(const TmpDir& dir, const Volume& vol) {
  Model m = create_model(ModelConfig::from_json(preset_config("tiny")), vol, 5);
  TrainOptions to{1024, 5};
  CpuTrainer tr(*m.net, std::make_shared<InCoreSampler>(vol), to);
  tr.run(20);
  save_model(dir / "m.vnr", m);
  return load_model(dir / "m.vnr");
}

struct Recorder {
  std::map<std::string, double> last;
  std::map<std::string, int> finished;
  std::vector<std::string> notes;
  FileEvalProgress callbacks() {
    FileEvalProgress p;
    p.update = [this](const std::string& stage, double f) { last[stage] = f; };
    p.finished = [this](const std::string& stage) { ++finished[stage]; };
    p.note = [this](const std::string& text) { notes.push_back(text); };
    return p;
  }
};

}  // namespace

TEST(FileEvaluation, InMemoryEqualsEvaluate) {
  TmpDir dir;
  synth_volume("marschner-lobb", kDims, dir / "v.json");
  const Volume vol = open_volume(dir / "v.json");
  const Model m = trained_model(dir, vol);
  const EvalResult ref = evaluate(*m.net, vol, true);

  FileEvalOptions o;
  o.model_path = dir / "m.vnr";
  Recorder rec;
  const FileEvaluation ev = evaluate_model_file(m, dir / "v.json", o, rec.callbacks());
  EXPECT_EQ(ev.plan.method, EvalMethod::Full);
  EXPECT_EQ(ev.device, Device::Cpu);
  EXPECT_EQ(ev.psnr, ref.psnr);
  EXPECT_EQ(ev.mse, ref.mse);
  ASSERT_TRUE(ev.ssim.has_value());
  EXPECT_EQ(*ev.ssim, ref.ssim);
  EXPECT_EQ(ev.max_abs_error, ref.max_abs_error);
  EXPECT_EQ(ev.max_abs_error_original, ref.max_abs_error_original);
  EXPECT_FALSE(ev.psnr_ci95.has_value());
  EXPECT_EQ(ev.samples, int64_t(kDims.count()));
  EXPECT_EQ(ev.value_range_source, "volume");
  EXPECT_EQ(ev.value_range.lo, vol.lo);
  EXPECT_EQ(ev.value_range.hi, vol.hi);
  EXPECT_EQ(ev.model_bytes, file_size(dir / "m.vnr"));
  EXPECT_EQ(ev.volume_bytes, kDims.count() * sizeof(float));
  EXPECT_DOUBLE_EQ(ev.compression_ratio, double(ev.volume_bytes) / double(ev.model_bytes));
  EXPECT_TRUE(ev.notes.empty());
  EXPECT_TRUE(rec.notes.empty());
  EXPECT_TRUE(rec.finished.empty());

  // Without a model file: the ratio against the fp16 parameters; no SSIM when not asked.
  o.model_path.clear();
  o.with_ssim = false;
  const FileEvaluation bare = evaluate_model_file(m, dir / "v.json", o);
  EXPECT_EQ(bare.model_bytes, m.param_bytes());
  EXPECT_FALSE(bare.ssim.has_value());
  EXPECT_EQ(bare.psnr, ref.psnr);
}

// A sidecar of dir/v.raw without the value range synth writes: the range then comes from elsewhere.
std::string write_sidecar_without_range(const TmpDir& dir) {
  Json side = parse_json_file(dir / "v.json");
  side.erase("value_range");
  std::ofstream(dir / "norange.json") << side.dump();
  return dir / "norange.json";
}

TEST(FileEvaluation, OverTheBudgetStreamsWithTheSameNumbers) {
  TmpDir dir;
  synth_volume("marschner-lobb", kDims, dir / "v.json");
  const std::string norange = write_sidecar_without_range(dir);
  const Volume vol = open_volume(norange);
  const Model m = trained_model(dir, vol);
  const EvalResult ref = evaluate(*m.net, vol, true);

  FileEvalOptions o;
  o.memory_budget = 1024;
  o.model_path = dir / "m.vnr";
  Recorder rec;
  const FileEvaluation ev = evaluate_model_file(m, norange, o, rec.callbacks());
  EXPECT_EQ(ev.plan.method, EvalMethod::Streamed);
  EXPECT_EQ(ev.plan.slab_slices, 1);
  EXPECT_NEAR(ev.psnr, ref.psnr, 1e-9 * std::fabs(ref.psnr));
  ASSERT_TRUE(ev.ssim.has_value());
  EXPECT_NEAR(*ev.ssim, ref.ssim, 1e-9);
  EXPECT_EQ(ev.max_abs_error, ref.max_abs_error);
  EXPECT_EQ(ev.samples, int64_t(kDims.count()));
  EXPECT_EQ(ev.value_range_source, "model");  // the sidecar states no range; the model file does
  ASSERT_EQ(ev.notes.size(), 1u);
  EXPECT_HAS(ev.notes[0], "streamed slabs of 1 slices");
  EXPECT_EQ(rec.notes, ev.notes);
  EXPECT_EQ(rec.last["eval"], 1.0);
  EXPECT_EQ(rec.finished["eval"], 1);
  EXPECT_EQ(rec.finished.count("value range"), 0u);

  // Without the model file's range the volume is scanned once, with its own progress stage.
  o.model_path.clear();
  Recorder scan;
  const FileEvaluation es = evaluate_model_file(m, norange, o, scan.callbacks());
  EXPECT_EQ(es.value_range_source, "scan");
  EXPECT_EQ(es.value_range.lo, vol.lo);
  EXPECT_EQ(es.value_range.hi, vol.hi);
  EXPECT_EQ(scan.finished["value range"], 1);
  EXPECT_EQ(es.max_abs_error, ref.max_abs_error);
}

TEST(FileEvaluation, SamplesWhenAskedAndNotesAnotherResolution) {
  TmpDir dir;
  synth_volume("marschner-lobb", kDims, dir / "v.json");
  const Volume vol = open_volume(dir / "v.json");
  const Model m = trained_model(dir, vol);
  const EvalResult ref = evaluate(*m.net, vol, false);

  FileEvalOptions o;
  o.samples = 3000;
  o.seed = 4;
  o.model_path = dir / "m.vnr";
  const FileEvaluation ev = evaluate_model_file(m, dir / "v.json", o);
  EXPECT_EQ(ev.plan.method, EvalMethod::Sampled);
  EXPECT_EQ(ev.samples, 3000);
  EXPECT_FALSE(ev.ssim.has_value());
  ASSERT_TRUE(ev.psnr_ci95.has_value());
  EXPECT_LE(ev.psnr_ci95->first, ref.psnr);
  EXPECT_GE(ev.psnr_ci95->second, ref.psnr);
  EXPECT_GT(ev.mse_stderr, 0);
  EXPECT_LE(ev.max_abs_error, ref.max_abs_error);
  const SampledEval direct = evaluate_sampled(*m.net, describe_volume_file(dir / "v.json"), ev.value_range.lo,
                                              ev.value_range.hi, 3000, 4);
  EXPECT_EQ(ev.psnr, direct.psnr);

  // A volume at another resolution: evaluated, with a note saying so.
  synth_volume("marschner-lobb", {10, 9, 6}, dir / "small.json");
  o.samples = 0;
  const FileEvaluation small = evaluate_model_file(m, dir / "small.json", o);
  ASSERT_EQ(small.notes.size(), 1u);
  EXPECT_EQ(small.notes[0], "model was trained on 20x18x11, evaluating at 10x9x6");
  EXPECT_EQ(small.samples, 10 * 9 * 6);
}

TEST(FileEvaluation, BadInputFailsWithOneError) {
  TmpDir dir;
  synth_volume("marschner-lobb", kDims, dir / "v.json");
  const Model m = trained_model(dir, open_volume(dir / "v.json"));
  FileEvalOptions o;
  o.samples = -5;
  EXPECT_HAS(error_of([&] { evaluate_model_file(m, dir / "v.json", o); }), "positive");
  o.samples = 0;
  EXPECT_HAS(error_of([&] { evaluate_model_file(m, dir / "missing.json", o); }), "missing.json");
  o.model_path = dir / "missing.vnr";
  EXPECT_HAS(error_of([&] { evaluate_model_file(m, dir / "v.json", o); }), "missing.vnr");
}
