#include "vnr/train/decoder.h"
#include <vector>
#include "vnr/train/model_form.h"
#include "vnr/volume/volume.h"

namespace vnr {

Decoder::Decoder(const Network& net, Device device, const Residuals* residuals)
    : net_(net), residuals_(residuals), device_(device), eval_(network_evaluator(net, device)) {}
Decoder::Decoder(const Model& model, Device device, cuda::MlpPath mlp)
    : net_(*model.net),
      residuals_(model.residuals ? &*model.residuals : nullptr),
      device_(device),
      eval_(form_of(model).evaluator(model, device, mlp)) {}
Decoder::~Decoder() = default;

cuda::GpuNetwork* Decoder::gpu() { return eval_->gpu(); }

bool Decoder::reload_device_params(const void* device_half) {
  cuda::GpuNetwork* g = gpu();
  if (!g || residuals_ || !device_half) return false;
  g->reload_params(device_half);
  return true;
}

Device evaluation_device(const Model& model, Device asked) { return form_of(model).evaluation_device(model, asked); }

void Decoder::slices(Int3 dims, int64_t z0, int64_t z1, float* out) {
  if (bounded_at(dims)) {
    if (!residuals_->absolute) reference_slices(net_, dims, z0, z1, out);  // absolute: q * step alone
    return apply_residuals(*residuals_, z0, z1, out);
  }
  eval_->slices(dims, z0, z1, out);
}

void Decoder::voxels(Int3 dims, const int64_t* voxel_index, int64_t n, float* out) {
  if (bounded_at(dims)) {
    const Residuals& r = *residuals_;
    if (r.absolute)
      for (int64_t i = 0; i < n; ++i) out[i] = r.correction(voxel_index[i]);
    else {
      reference_voxels(net_, dims, voxel_index, n, out);
      for (int64_t i = 0; i < n; ++i) out[i] += r.correction(voxel_index[i]);
    }
    return;
  }
  eval_->voxels(dims, voxel_index, n, out);
}

void Decoder::points(const float* xyz, int64_t n, float* out) {
  if (n > 0) eval_->points(xyz, n, out);
}

void decode_slices(const Network& net, Int3 dims, int64_t z0, int64_t z1, float* out) {
  Decoder(net, Device::Cpu).slices(dims, z0, z1, out);
}
void decode_voxels(const Network& net, Int3 dims, const int64_t* voxel_index, int64_t n, float* out) {
  Decoder(net, Device::Cpu).voxels(dims, voxel_index, n, out);
}

}  // namespace vnr
