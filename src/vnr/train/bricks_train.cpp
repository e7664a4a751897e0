// Training one brick of a multi-brick model from its region of the volume (train/bricks.h).
#include <chrono>
#include "vnr/core/error.h"
#include "vnr/core/fileio.h"
#include "vnr/core/units.h"
#include "vnr/train/bricks.h"
#include "vnr/train/evaluate.h"
#include "vnr/volume/raw_access.h"

namespace vnr {

ValueRange brick_value_range(const TrainingSetup& setup, const MessageFn& message) {
  const VolumeDesc desc = describe_volume(setup.volume, setup.raw);
  if (desc.range_lo && desc.range_hi) return ValueRange{*desc.range_lo, *desc.range_hi};
  if (message) message(fmt::format("scanning {} for its value range (every brick normalises with it)", setup.volume));
  return scan_value_range(desc, setup.load);
}

namespace {

// The brick's trained box read with pread and normalised with the whole volume's range.
std::shared_ptr<Volume> read_brick_volume(const TrainingSetup& setup, const BrickPlan& plan, const BrickSpec& b,
                                          const ValueRange& range) {
  const VolumeDesc desc = describe_volume(setup.volume, setup.raw);
  if (!(desc.dims == plan.dims))
    fail("'{}' has {}x{}x{} voxels but the brick plan is for {}x{}x{}", setup.volume, desc.dims.x, desc.dims.y,
         desc.dims.z, plan.dims.x, plan.dims.y, plan.dims.z);
  const uint64_t need = b.trained.voxels() * sizeof(float);
  const uint64_t budget = setup.data.memory_budget ? setup.data.memory_budget : available_memory_bytes() / 2;
  if (need > budget)
    fail("brick {} needs {} MiB in memory ({}x{}x{} voxels with ghosts), more than the memory budget of {} MiB; "
         "use more bricks (--bricks)",
         b.index, need >> 20, b.trained.size().x, b.trained.size().y, b.trained.size().z, budget >> 20);
  RawVolumeFile file(desc, range.lo, range.hi, setup.load.non_finite, "brick training",
                     "convert the volume to raw or NRRD (uncompressed)");
  auto v = std::make_shared<Volume>();
  v->dims = b.trained.size();
  v->source_dtype = desc.dtype;
  v->lo = range.lo;
  v->hi = range.hi;
  v->data.resize(v->dims.count());
  std::vector<unsigned char> scratch(file.scratch_bytes(v->dims));
  file.read_box(b.trained.lo, v->dims, v->data.data(), scratch.data());
  return v;
}

}  // namespace

BrickResult train_brick(const TrainingSetup& setup, const BrickPlan& plan, int index, const std::string& out_dir,
                        const ValueRange& range, const BrickTrainOptions& o) {
  if (index < 0 || size_t(index) >= plan.bricks.size()) fail("brick {} is not in the plan (0..{})", index, plan.bricks.size() - 1);
  const BrickSpec& b = plan.bricks[size_t(index)];
  std::shared_ptr<const Volume> vol = read_brick_volume(setup, plan, b, range);

  TrainingSetup s = setup;
  s.volume = fmt::format("{} brick {}", setup.volume, index);
  s.seed = b.seed;
  s.data.sampler = "";
  s.steps = o.steps;
  s.session.output = join_path(out_dir, b.file);
  // --target-ratio is the whole model's: each brick gets the parameters of its owned voxels.
  if (setup.target_ratio > 0) s.target_ratio = setup.target_ratio * double(b.trained.voxels()) / double(b.owned.voxels());
  std::unique_ptr<TrainingSession> session = open_training_session(s, vol, o.message);
  if (o.on_step) session->add_step_callback(o.on_step);
  if (o.stop)
    session->add_step_callback([&](const TrainingProgress&) {
      if (o.stop->load()) session->request_stop();
    });
  session->run(o.steps, o.seconds);

  BrickResult r;
  r.index = index;
  r.steps = session->steps_done();
  r.seconds = session->training_seconds();
  r.final_loss = session->last_loss();
  r.interrupted = session->stop_requested();
  session->record();
  Model& m = session->model();
  const EvalResult ev = evaluate(*m.net, *vol, o.with_ssim, Device::Cpu);
  r.psnr = ev.psnr;
  r.n_params = m.net->n_params();
  Json rec = brick_record(b);
  rec["complete"] = !r.interrupted;
  rec["config"] = setup.config_json ? setup.config_json->dump() : setup.config;
  rec["psnr"] = ev.psnr;
  m.training["brick"] = rec;
  save_model(s.session.output, m);  // atomic: a brick file is whole or absent
  r.file_bytes = file_size(s.session.output);
  return r;
}

}  // namespace vnr
