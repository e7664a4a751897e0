// How a model is evaluated against a volume file of any size: the method, the slab size and the range.
#include <algorithm>
#include "vnr/core/units.h"
#include "vnr/model.h"

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

}  // namespace vnr
