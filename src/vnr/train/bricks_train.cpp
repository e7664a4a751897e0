// Training one brick of a multi-brick model from its region of the volume (train/bricks.h).
#include <algorithm>
#include <chrono>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/units.h"
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

// The volume file, checked against the plan.
VolumeDesc brick_source(const TrainingSetup& setup, const BrickPlan& plan) {
  const VolumeDesc desc = describe_volume(setup.volume, setup.raw);
  if (!(desc.dims == plan.dims))
    fail("'{}' has {}x{}x{} voxels but the brick plan is for {}x{}x{}", setup.volume, desc.dims.x, desc.dims.y,
         desc.dims.z, plan.dims.x, plan.dims.y, plan.dims.z);
  return desc;
}

RawVolumeFile brick_file(const VolumeDesc& desc, const TrainingSetup& setup, const ValueRange& range) {
  return RawVolumeFile(desc, range.lo, range.hi, setup.load.non_finite, "brick training",
                       "convert the volume to raw or NRRD (uncompressed)");
}

std::string box_text(const Box3& b) { return fmt::format("{}x{}x{}", b.size().x, b.size().y, b.size().z); }

// Whether brick b trains out of core: --sampler outofcore, or (no --sampler) its trained box as float
// does not fit the memory budget. `why` gets the reason for people.
bool brick_out_of_core(const TrainingSetup& setup, const BrickSpec& b, uint64_t budget, std::string* why) {
  const std::string& sampler = setup.data.sampler;
  if (sampler == "mmap") fail("--sampler mmap is not supported with bricks (they train in core or out of core)");
  if (!sampler.empty() && sampler != "incore" && sampler != "outofcore")
    fail("unknown --sampler '{}' (allowed: incore, outofcore)", sampler);
  const uint64_t need = b.trained.voxels() * sizeof(float);
  if (sampler == "outofcore") {
    *why = "--sampler outofcore";
    return true;
  }
  if (need <= budget) return false;
  if (sampler == "incore")
    fail("brick {} needs {} in memory ({} voxels with ghosts), more than the memory budget of {}; omit --sampler "
         "incore to train it out of core, or raise --memory-budget",
         b.index, human_bytes(double(need)), box_text(b.trained), human_bytes(double(budget)));
  *why = fmt::format("its {} voxels with ghosts need {} as float, more than the memory budget of {}",
                     box_text(b.trained), human_bytes(double(need)), human_bytes(double(budget)));
  return true;
}

// The brick's trained box read with pread and normalised with the whole volume's range.
std::shared_ptr<Volume> read_brick_volume(const VolumeDesc& desc, const TrainingSetup& setup, const BrickSpec& b,
                                          const ValueRange& range) {
  const RawVolumeFile file = brick_file(desc, setup, range);
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

// The brick's session: on its box in memory, or out of core on its box of the file.
std::unique_ptr<TrainingSession> open_brick_session(const TrainingSetup& s, const VolumeDesc& desc, const BrickSpec& b,
                                                    const ValueRange& range, bool out_of_core, uint64_t budget,
                                                    const MessageFn& message) {
  if (!out_of_core) {
    TrainingSetup in_core = s;
    in_core.volume = fmt::format("{} brick {}", s.volume, b.index);
    in_core.data.sampler = "";
    return open_training_session(in_core, read_brick_volume(desc, s, b, range), message);
  }
  TrainingSetup ooc = s;
  ooc.data.sampler = "outofcore";
  ooc.data.region = b.trained;
  ooc.data.range = range;
  ooc.data.memory_budget = budget;
  try {
    return open_training_session(ooc, message);
  } catch (const Error& e) {
    fail("brick {} trains out of core, but {}", b.index, e.what());
  }
}

}  // namespace

BrickResult train_brick(const TrainingSetup& setup, const BrickPlan& plan, int index, const std::string& out_dir,
                        const ValueRange& range, const BrickTrainOptions& o) {
  if (index < 0 || size_t(index) >= plan.bricks.size()) fail("brick {} is not in the plan (0..{})", index, plan.bricks.size() - 1);
  const BrickSpec& b = plan.bricks[size_t(index)];
  const VolumeDesc desc = brick_source(setup, plan);
  const uint64_t budget = setup.data.memory_budget ? setup.data.memory_budget : available_memory_bytes() / 2;
  std::string why;
  const bool out_of_core = brick_out_of_core(setup, b, budget, &why);
  if (out_of_core && o.message) o.message(fmt::format("note: brick {} trains out of core: {}", index, why));

  TrainingSetup s = setup;
  s.seed = b.seed;
  s.steps = o.steps;
  s.session.output = join_path(out_dir, b.file);
  s.residuals = "off";  // a brick file holds no residuals
  // --target-ratio is the whole model's: each brick gets the parameters of its owned voxels.
  if (setup.target_ratio > 0) s.target_ratio = setup.target_ratio * double(b.trained.voxels()) / double(b.owned.voxels());
  std::unique_ptr<TrainingSession> session = open_brick_session(s, desc, b, range, out_of_core, budget, o.message);
  if (o.on_step) session->add_step_callback(o.on_step);
  if (o.stop)
    session->add_step_callback([&](const TrainingProgress&) {
      if (o.stop->load()) session->request_stop();
    });
  session->set_budget(o.steps, o.seconds);
  session->run(o.steps, o.seconds);

  BrickResult r;
  r.index = index;
  r.steps = session->steps_done();
  r.seconds = session->training_seconds();
  r.final_loss = session->last_loss();
  r.interrupted = session->stop_requested();
  // Sized for the ratio, stored as trained (docs/MODEL_FORMAT.md "Sizes"); evaluated on its region and
  // saved with its record below.
  session->finish({.quantize = false, .evaluate = false, .save = false});
  Model& m = session->model();
  // Out of core the brick is never held: it is evaluated in slabs of a sixteenth of the budget (two or
  // three float copies of a slab, plus the decoder's).
  if (out_of_core) {
    const RawVolumeFile file = brick_file(desc, setup, range);
    const int64_t slab_voxels = std::max<int64_t>(1, int64_t(budget / 16 / sizeof(float)));
    r.psnr = evaluate_box_slices(*m.net, file, b.trained, 0, b.trained.size().z, o.with_ssim, slab_voxels).result(1).psnr;
  } else {
    r.psnr = evaluate(*m.net, *session->data()->vol, o.with_ssim, Device::Cpu).psnr;
  }
  r.n_params = m.net->n_params();
  Json rec = brick_record(b);
  rec["complete"] = !r.interrupted;
  rec["config"] = setup.config_json ? setup.config_json->dump() : setup.config;
  rec["psnr"] = r.psnr;
  rec["sampler"] = out_of_core ? "outofcore" : "incore";
  m.training["brick"] = rec;
  save_model(s.session.output, m);  // atomic: a brick file is whole or absent
  r.file_bytes = file_size(s.session.output);
  return r;
}

}  // namespace vnr
