// The single network's ModelForm, the network evaluators, and form_of (train/model_form.h).
#include "vnr/train/model_form.h"
#include <vector>
#include "vnr/error.h"
#include "vnr/train/model.h"
#include "vnr/units.h"
#include "vnr/volume/volume.h"

namespace vnr {

void ModelEvaluator::voxels(Int3 dims, const int64_t* voxel_index, int64_t n, float* out) {
  std::vector<float> xyz(size_t(3 * n));
  for (int64_t i = 0; i < n; ++i) voxel_centre(dims, voxel_index[i], &xyz[3 * i], &xyz[3 * i + 1], &xyz[3 * i + 2]);
  points(xyz.data(), n, out);
}

namespace {

class CpuNetworkEvaluator final : public ModelEvaluator {
public:
  explicit CpuNetworkEvaluator(const Network& net) : net_(net) {}
  void points(const float* xyz, int64_t n, float* out) override { net_.infer(xyz, n, out); }
  void slices(Int3 dims, int64_t z0, int64_t z1, float* out) override {
    const int64_t first = dims.x * dims.y * z0;
    net_.infer_fn(
        dims.x * dims.y * (z1 - z0),
        [&](int64_t i, float* x, float* y, float* z) { voxel_centre(dims, first + i, x, y, z); }, out);
  }
  void voxels(Int3 dims, const int64_t* voxel_index, int64_t n, float* out) override {
    net_.infer_fn(
        n, [&](int64_t i, float* x, float* y, float* z) { voxel_centre(dims, voxel_index[i], x, y, z); }, out);
  }

private:
  const Network& net_;
};

class GpuNetworkEvaluator final : public ModelEvaluator {
public:
  GpuNetworkEvaluator(const Network& net, cuda::MlpPath mlp) : gpu_(net, mlp) {}
  void points(const float* xyz, int64_t n, float* out) override { gpu_.infer(xyz, n, out); }
  void slices(Int3 dims, int64_t z0, int64_t z1, float* out) override {
    gpu_.decode_slices(dims, z0, z1, out);  // voxel_centre() in kernels.cu
  }
  cuda::GpuNetwork* gpu() override { return &gpu_; }

private:
  cuda::GpuNetwork gpu_;
};

class NetworkForm final : public ModelForm {
public:
  uint64_t n_params(const Model& m) const override { return m.net->n_params(); }
  bool trainable() const override { return true; }
  Device evaluation_device(const Model& m, Device asked) const override {
    if (asked == Device::Cuda) cuda::check_supported(*m.net);
    return asked;
  }
  std::unique_ptr<ModelEvaluator> evaluator(const Model& m, Device device, cuda::MlpPath mlp) const override {
    return network_evaluator(*m.net, device, mlp);
  }
  std::string gpu_render_reason(const Model& m) const override { return cuda::unsupported_reason(*m.net); }
  void describe(const Model&, Json&) const override {}
  void check_savable(const Model&, const std::string&) const override {}
  void make_field(const Model& m, ModelFieldMaker& maker) const override { maker.network(m); }
};

}  // namespace

std::unique_ptr<ModelEvaluator> network_evaluator(const Network& net, Device device, cuda::MlpPath mlp) {
  if (device == Device::Cuda) return std::make_unique<GpuNetworkEvaluator>(net, mlp);
  return std::make_unique<CpuNetworkEvaluator>(net);
}

const ModelForm& network_form() {
  static const NetworkForm form;
  return form;
}

const ModelForm& form_of(const Model& m) { return m.bricks ? bricks_form() : network_form(); }

std::string gpu_decode_reason(const std::string& what, Int3 dims) {
  const double bytes = double(dims.count()) * sizeof(float);
  if (bytes > double(cuda::free_memory_bytes()) / 4)
    return fmt::format("{} renders on the GPU from its decode ({}), more than a quarter of the GPU's free memory ({})",
                       what, human_bytes(bytes), human_bytes(double(cuda::free_memory_bytes())));
  if (bytes > double(available_memory_bytes()))
    return fmt::format("{} renders on the GPU from its decode ({}), more than the memory available", what,
                       human_bytes(bytes));
  return {};
}

uint64_t Model::n_params() const { return form_of(*this).n_params(*this); }
bool Model::trainable() const { return form_of(*this).trainable(); }

}  // namespace vnr
