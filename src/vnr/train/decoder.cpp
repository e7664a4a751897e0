#include "vnr/train/decoder.h"
#include <vector>
#include "vnr/train/bricks.h"
#include "vnr/volume/volume.h"

namespace vnr {

Decoder::Decoder(const Network& net, Device device, const Residuals* residuals)
    : net_(net), residuals_(residuals), device_(device) {
  if (device == Device::Cuda) gpu_ = std::make_unique<cuda::GpuNetwork>(net);
}
Decoder::Decoder(const Model& model, Device device, cuda::MlpPath mlp)
    : net_(*model.net),
      residuals_(model.residuals ? &*model.residuals : nullptr),
      device_(device),
      bricks_(model.bricks.get()) {
  if (bricks_) set_inference_precision(*model.bricks, model.net->inference_precision());
  if (device_ != Device::Cuda) return;
  if (bricks_) brick_gpus_ = std::make_unique<BrickGpuNetworks>(*bricks_, mlp);
  else gpu_ = std::make_unique<cuda::GpuNetwork>(net_, mlp);
}
Decoder::~Decoder() = default;

Device evaluation_device(const Model& model, Device asked) {
  if (model.bricks) return Device::Cpu;
  if (asked == Device::Cuda) cuda::check_supported(*model.net);
  return asked;
}

BrickInfer Decoder::brick_infer() { return brick_gpus_ ? brick_gpus_->fn() : BrickInfer{}; }

void Decoder::slices(Int3 dims, int64_t z0, int64_t z1, float* out) {
  if (bricks_)
    return decode_bricked_region(*bricks_, dims, Box3{{0, 0, z0}, {dims.x, dims.y, z1}}, out, brick_infer());
  if (bounded_at(dims)) {
    if (!residuals_->absolute) reference_slices(net_, dims, z0, z1, out);  // absolute: q * step alone
    return apply_residuals(*residuals_, z0, z1, out);
  }
  if (gpu_) return gpu_->decode_slices(dims, z0, z1, out);  // voxel_centre() in kernels.cu
  const int64_t first = dims.x * dims.y * z0;
  net_.infer_fn(
      dims.x * dims.y * (z1 - z0), [&](int64_t i, float* x, float* y, float* z) { voxel_centre(dims, first + i, x, y, z); },
      out);
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
  if (gpu_ || bricks_) {
    std::vector<float> xyz(size_t(3 * n));
    for (int64_t i = 0; i < n; ++i) voxel_centre(dims, voxel_index[i], &xyz[3 * i], &xyz[3 * i + 1], &xyz[3 * i + 2]);
    return bricks_ ? bricked_points(*bricks_, xyz.data(), n, out, brick_infer()) : gpu_->infer(xyz.data(), n, out);
  }
  net_.infer_fn(
      n, [&](int64_t i, float* x, float* y, float* z) { voxel_centre(dims, voxel_index[i], x, y, z); }, out);
}

void Decoder::points(const float* xyz, int64_t n, float* out) {
  if (n <= 0) return;
  if (bricks_) return bricked_points(*bricks_, xyz, n, out, brick_infer());
  if (gpu_) return gpu_->infer(xyz, n, out);
  net_.infer(xyz, n, out);
}

void decode_slices(const Network& net, Int3 dims, int64_t z0, int64_t z1, float* out) {
  Decoder(net, Device::Cpu).slices(dims, z0, z1, out);
}
void decode_voxels(const Network& net, Int3 dims, const int64_t* voxel_index, int64_t n, float* out) {
  Decoder(net, Device::Cpu).voxels(dims, voxel_index, n, out);
}

}  // namespace vnr
