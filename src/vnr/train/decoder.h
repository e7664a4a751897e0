#pragma once
// Decoding a network at voxel centres on the CPU or the GPU.
#include <cstdint>
#include <functional>
#include <memory>
#include "vnr/device.h"
#include "vnr/math.h"
#include "vnr/cuda/cuda.h"
#include "vnr/nn/network.h"
#include "vnr/train/residuals.h"

namespace vnr {

struct Model;
class ModelEvaluator;  // train/model_form.h

// Decodes a network at voxel centres ((i + 0.5) / n per axis) on one backend; a GPU decoder keeps its
// copy of the network between calls. On the GPU the network runs in half precision (tcnn's inference),
// so values differ from the CPU's by about 1e-3 relative.
//
// With residuals (error-bound models), a decode at the residuals' dims is the CPU reference
// (reference_slices) plus the residuals, on every device, so the bound holds whichever device was
// asked for; other dims decode the network alone (the bound is defined at the volume's voxels only).
class Decoder {
public:
  Decoder(const Network& net, Device device, const Residuals* residuals = nullptr);
  // A model's decoder: its residuals apply (error-bound models); its form's evaluator does the rest (a
  // multi-brick model blends its bricks, each brick's network on the device, at the model's precision).
  Decoder(const Model& model, Device device, cuda::MlpPath mlp = cuda::MlpPath::Auto);
  ~Decoder();
  // z-slices [z0, z1) of `dims` into out (normalised units), x fastest.
  void slices(Int3 dims, int64_t z0, int64_t z1, float* out);
  // n voxels given by index (x + dims.x * (y + dims.y * z)): bit-identical to what slices() gives them.
  void voxels(Int3 dims, const int64_t* voxel_index, int64_t n, float* out);
  // n points, interleaved x, y, z in [0, 1)^3: the network (or blended bricks) alone, no residuals.
  void points(const float* xyz, int64_t n, float* out);
  cuda::GpuNetwork* gpu();  // the GPU copy of a single network (null otherwise)
  // A GPU decoder of a single network without residuals takes a trainer's new parameters in place,
  // device to device (GpuNetwork::reload_params); false otherwise (build a new decoder).
  bool reload_device_params(const void* device_half);
  Device device() const { return device_; }
  // Whether a decode at dims applies the residuals.
  bool bounded_at(Int3 dims) const { return residuals_ && residuals_->dims == dims; }

private:
  const Network& net_;  // the CPU reference under residuals
  const Residuals* residuals_;
  Device device_;
  std::unique_ptr<ModelEvaluator> eval_;
};

// The device a file evaluation of `model` decodes on when `asked` was asked for (ModelForm): a multi-brick
// model's on the CPU; a network the GPU cannot run fails here, before anything is read.
Device evaluation_device(const Model& model, Device asked);

// Decoder(net, Device::Cpu).slices / .voxels.
void decode_slices(const Network& net, Int3 dims, int64_t z0, int64_t z1, float* out);
void decode_voxels(const Network& net, Int3 dims, const int64_t* voxel_index, int64_t n, float* out);

}  // namespace vnr
