// The single-process training of a whole multi-brick model, and its output directory (train/bricks.h).
#include <chrono>
#include <filesystem>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/progress.h"
#include "vnr/train/bricks.h"

namespace vnr {

namespace fs = std::filesystem;

void prepare_brick_dir(const std::string& dir, const BrickPlan& plan, bool resume) {
  std::error_code ec;
  if (fs::exists(dir, ec) && !fs::is_directory(dir, ec))
    fail("'{}' is a file; a multi-brick model is a directory (-o DIR)", dir);
  if (fs::is_directory(dir, ec) && !fs::is_empty(dir, ec)) {
    const std::string manifest = join_path(dir, "manifest.json");
    if (!resume)
      fail("'{}' already exists and is not empty; --resume continues its training, or choose another -o", dir);
    if (!file_exists(manifest)) fail("--resume: '{}' holds no manifest.json, so it is not a multi-brick model", dir);
    const BrickPlan old = read_manifest_plan(parse_json_file(manifest), manifest);
    if (!(old.dims == plan.dims) || !(old.grid == plan.grid) || old.ghost != plan.ghost || old.seed != plan.seed)
      fail("--resume: '{}' was started with {}x{}x{} voxels, bricks {},{},{}, --ghost {} and --seed {}; this run asks for "
           "{}x{}x{}, {},{},{}, {} and {}",
           dir, old.dims.x, old.dims.y, old.dims.z, old.grid.x, old.grid.y, old.grid.z, old.ghost, old.seed, plan.dims.x,
           plan.dims.y, plan.dims.z, plan.grid.x, plan.grid.y, plan.grid.z, plan.ghost, plan.seed);
    return;
  }
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir)) fail("cannot create '{}': {}", dir, ec ? ec.message() : "unknown error");
}

std::vector<BrickResult> brick_results_on_disk(const std::string& dir, const BrickPlan& plan,
                                               const std::vector<bool>& done) {
  std::vector<BrickResult> out;
  for (const BrickSpec& b : plan.bricks) {
    if (!done[size_t(b.index)]) continue;
    const Model m = load_model(join_path(dir, b.file));
    BrickResult r;
    r.index = b.index;
    r.steps = m.training.value("steps", int64_t(0));
    r.seconds = m.training.value("seconds", 0.0);
    r.final_loss = m.training.value("final_loss", 0.f);
    r.psnr = m.training["brick"].value("psnr", 0.0);
    r.n_params = m.net->n_params();
    r.file_bytes = file_size(join_path(dir, b.file));
    out.push_back(r);
  }
  return out;
}

Json bricks_training_summary(const TrainingSetup& setup, const BrickPlan& plan, const std::vector<BrickResult>& done,
                             int64_t steps_per_brick) {
  int64_t steps = 0;
  double seconds = 0;
  for (const BrickResult& b : done) steps += b.steps, seconds += b.seconds;
  return Json{{"bricks_done", done.size()},
              {"bricks", plan.bricks.size()},
              {"complete", done.size() == plan.bricks.size()},
              {"steps_per_brick", steps_per_brick >= 0 ? Json(steps_per_brick) : Json(nullptr)},
              {"brick_steps", steps},
              {"brick_seconds", seconds},
              {"batch", setup.batch},
              {"seed", setup.seed},
              {"target_ratio", setup.target_ratio}};
}

BricksRunResult train_bricks(const TrainingSetup& setup, Int3 grid, int ghost, const std::string& out_dir,
                             const BricksRunOptions& o) {
  check_training_setup(setup);
  const auto t0 = std::chrono::steady_clock::now();
  BricksRunResult r;
  const VolumeDesc desc = describe_volume(setup.volume, setup.raw);
  r.plan = plan_bricks(desc.dims, grid, ghost, setup.seed);
  prepare_brick_dir(out_dir, r.plan, o.resume);
  r.range = brick_value_range(setup, o.brick.message);
  const Json config = setup.config_json ? *setup.config_json : Json(setup.config);
  const std::string config_text = setup.config_json ? setup.config_json->dump() : setup.config;
  std::vector<bool> done = bricks_done(out_dir, r.plan, config_text);
  for (bool d : done) r.already_done += d;
  write_manifest(out_dir, r.plan, desc.dtype, r.range, config, brick_results_on_disk(out_dir, r.plan, done));

  const int n_todo = int(r.plan.bricks.size()) - r.already_done;
  int k = 0;
  for (const BrickSpec& b : r.plan.bricks) {
    if (done[size_t(b.index)]) continue;
    if (o.brick.stop && o.brick.stop->load()) {
      r.interrupted = true;
      break;
    }
    if (o.on_brick_start) o.on_brick_start(b, k++, n_todo);
    BrickResult br = train_brick(setup, r.plan, b.index, out_dir, r.range, o.brick);
    if (o.on_brick_done) o.on_brick_done(br);
    r.trained.push_back(br);
    if (br.interrupted) {
      r.interrupted = true;
      break;
    }
    done[size_t(b.index)] = true;
  }
  for (bool d : done) r.done += d;
  r.complete = r.done == int(done.size());
  r.seconds = seconds_since(t0);
  const std::vector<BrickResult> all = brick_results_on_disk(out_dir, r.plan, done);
  const Json training = bricks_training_summary(setup, r.plan, all, o.brick.steps);
  write_manifest(out_dir, r.plan, desc.dtype, r.range, config, all, training);
  return r;
}

}  // namespace vnr
