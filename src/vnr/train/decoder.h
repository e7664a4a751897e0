#pragma once
// Decoding a network at voxel centres on the CPU or the GPU.
#include <cstdint>
#include <memory>
#include "vnr/core/device.h"
#include "vnr/core/math.h"
#include "vnr/cuda/cuda.h"
#include "vnr/nn/network.h"

namespace vnr {

struct BrickedModel;  // train/bricks.h
struct Model;

// Decodes a network at voxel centres ((i + 0.5) / n per axis) on one backend; a GPU decoder keeps its
// copy of the network between calls. On the GPU the network runs in half precision (tcnn's inference),
// so values differ from the CPU's by about 1e-3 relative.
class Decoder {
public:
  Decoder(const Network& net, Device device);
  // A model's decoder: a multi-brick model (Model::bricks) decodes its bricks blended, on the CPU.
  Decoder(const Model& model, Device device);
  ~Decoder();
  // z-slices [z0, z1) of `dims` into out (normalised units), x fastest.
  void slices(Int3 dims, int64_t z0, int64_t z1, float* out);
  // n voxels given by index (x + dims.x * (y + dims.y * z)): bit-identical to what slices() gives them.
  void voxels(Int3 dims, const int64_t* voxel_index, int64_t n, float* out);
  Device device() const { return device_; }

private:
  const Network& net_;
  Device device_;
  std::unique_ptr<cuda::GpuNetwork> gpu_;
  const BrickedModel* bricks_ = nullptr;
};

// Decoder(net, Device::Cpu).slices / .voxels.
void decode_slices(const Network& net, Int3 dims, int64_t z0, int64_t z1, float* out);
void decode_voxels(const Network& net, Int3 dims, const int64_t* voxel_index, int64_t n, float* out);

}  // namespace vnr
