// How a model is evaluated against a volume file of any size: the method, the slab size, the range,
// and the whole evaluation `vnr eval` runs.
#include <algorithm>
#include <fmt/format.h>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/units.h"
#include "vnr/model.h"
#include "vnr/train/bricks.h"
#include "vnr/train/training_data.h"

namespace vnr {

const char* eval_method_name(EvalMethod m) {
  switch (m) {
    case EvalMethod::Streamed: return "streamed";
    case EvalMethod::Sampled: return "sampled";
    case EvalMethod::Full:
    default: return "full";
  }
}

FileEvalPlan plan_file_evaluation(const VolumeDesc& desc, int64_t samples, bool with_ssim,
                                  std::optional<uint64_t> memory_budget) {
  FileEvalPlan p;
  p.desc = desc;
  p.budget = memory_budget ? *memory_budget : available_memory_bytes() / 2;
  const Int3 dims = desc.dims;
  p.full_bytes = dims.count() * 2 * sizeof(float);
  p.method = samples > 0 ? EvalMethod::Sampled : (p.full_bytes <= p.budget ? EvalMethod::Full : EvalMethod::Streamed);
  if (p.method != EvalMethod::Streamed) return p;
  const int64_t slice = dims.x * dims.y;
  const int64_t arrays = with_ssim ? 3 : 2, overlap = with_ssim ? 6 : 0;
  const int64_t budget_slices = int64_t(p.budget / (uint64_t(arrays) * sizeof(float) * uint64_t(slice))) - overlap;
  p.slab_slices = std::clamp<int64_t>(std::min(budget_slices, (int64_t(1) << 24) / slice), 1, dims.z);
  return p;
}

ValueRange file_evaluation_range(const FileEvalPlan& plan, const Model& model, bool model_file_records_range,
                                 const LoadOptions& load, std::string* source,
                                 const std::function<void(double fraction)>& progress) {
  const VolumeDesc& desc = plan.desc;
  if (desc.range_lo && desc.range_hi) {
    *source = "volume";
    return scan_value_range(desc, load);  // reads nothing
  }
  if (!desc.range_lo && !desc.range_hi && model_file_records_range) {
    *source = "model";
    return ValueRange{model.lo, model.hi};
  }
  *source = "scan";
  return scan_value_range(desc, load, progress);
}

namespace {


void note(FileEvaluation& r, const FileEvalProgress& progress, std::string text) {
  if (progress.note) progress.note(text);
  r.notes.push_back(std::move(text));
}

// The bound an error-bound model guarantees at its own dims, compared with the largest error found.
void check_bound(FileEvaluation& r, const Model& model, const FileEvalProgress& progress) {
  if (!model.residuals) return;
  r.error_bound_original = model.residuals->bound * (model.hi - model.lo);
  if (!(r.plan.desc.dims == model.dims)) {
    note(r, progress, "the error bound holds at the model's own dims only: not checked at other dims");
    r.error_bound_original.reset();
    return;
  }
  r.bound_holds = r.max_abs_error_original <= *r.error_bound_original;
}

void take_whole(FileEvaluation& r, const EvalResult& ev, bool with_ssim) {
  r.psnr = ev.psnr;
  r.mse = ev.mse;
  if (with_ssim) r.ssim = ev.ssim;
  r.max_abs_error = ev.max_abs_error;
  r.max_abs_error_original = ev.max_abs_error_original;
  r.samples = int64_t(r.plan.desc.dims.count());
  r.decode_seconds = ev.decode_seconds;
}

void take_sampled(FileEvaluation& r, const SampledEval& ev) {
  r.psnr = ev.psnr;
  r.psnr_ci95 = std::make_pair(ev.psnr_ci95_lo, ev.psnr_ci95_hi);
  r.mse = ev.mse;
  r.mse_stderr = ev.mse_stderr;
  r.max_abs_error = ev.max_abs_error;
  r.max_abs_error_original = ev.max_abs_error_original;
  r.samples = ev.samples;
  r.decode_seconds = ev.decode_seconds;
}

// Streamed and Sampled: the volume is never held, so its range comes first (maybe from a scan).
void evaluate_unheld(FileEvaluation& r, const Model& model, const FileEvalOptions& o, const FileEvalProgress& progress) {
  const FileEvalPlan& plan = r.plan;
  const bool records_range = !o.model_path.empty() && model_file_has_value_range(o.model_path);
  auto range_progress = [&](double f) {
    if (progress.update) progress.update("value range", f);
  };
  r.value_range = file_evaluation_range(plan, model, records_range, o.open.load, &r.value_range_source, range_progress);
  if (r.value_range_source == "scan" && progress.finished) progress.finished("value range");
  const double lo = r.value_range.lo, hi = r.value_range.hi;
  if (plan.method == EvalMethod::Sampled) {
    take_sampled(r, evaluate_sampled(model, plan.desc, lo, hi, o.samples, o.seed, o.open.load, o.device));
    return;
  }
  note(r, progress,
       fmt::format("evaluating in streamed slabs of {} slices: holding the volume and the decoded copy would take "
                   "{}, over the memory budget of {}",
                   plan.slab_slices, human_bytes(double(plan.full_bytes)), human_bytes(double(plan.budget))));
  const Int3 dims = plan.desc.dims;
  auto eval_progress = [&](double f) {
    if (progress.update) progress.update("eval", f);
  };
  const EvalResult ev = evaluate_streamed(model, plan.desc, lo, hi, o.open.load, o.with_ssim, eval_progress,
                                          plan.slab_slices * dims.x * dims.y, o.device);
  if (progress.finished) progress.finished("eval");
  take_whole(r, ev, o.with_ssim);
}

}  // namespace

FileEvaluation evaluate_model_file(const Model& model, const std::string& volume_path, const FileEvalOptions& o,
                                   const FileEvalProgress& progress) {
  if (!model.net) fail("the model has no network");
  if (o.samples < 0) fail("the number of sampled voxels must be positive, got {}", o.samples);
  FileEvaluation r;
  r.device = evaluation_device(model, o.device);  // before reading the volume
  const VolumeDesc desc = describe_volume_file(volume_path, o.open);
  const Int3 dims = desc.dims;
  if (!(dims == model.dims))
    note(r, progress,
         fmt::format("model was trained on {}x{}x{}, evaluating at {}x{}x{}", model.dims.x, model.dims.y,
                     model.dims.z, dims.x, dims.y, dims.z));
  r.model_bytes = o.model_path.empty() ? model.param_bytes() : model_file_bytes(o.model_path);
  r.volume_bytes = dims.count() * dtype_size(desc.dtype);
  r.compression_ratio = double(r.volume_bytes) / double(r.model_bytes);
  r.plan = plan_file_evaluation(desc, o.samples, o.with_ssim, o.memory_budget);
  if (r.plan.method != EvalMethod::Full) {
    evaluate_unheld(r, model, o, progress);
    check_bound(r, model, progress);
    return r;
  }
  const Volume vol = load_volume(desc, o.open.load);
  r.value_range = {vol.lo, vol.hi};
  r.value_range_source = "volume";
  take_whole(r, evaluate_model(model, vol, o.with_ssim, o.device), o.with_ssim);
  check_bound(r, model, progress);
  return r;
}

}  // namespace vnr
