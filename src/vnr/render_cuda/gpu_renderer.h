#pragma once
// Rendering on the GPU (paper "Rendering"): the integrators of render/integrators.h -- the same VNR_HD
// functions the CPU renderer calls -- launched as CUDA kernels, for a trained network or the
// ground-truth grid, in both execution strategies:
//  - in-shader: one thread per pixel runs its whole ray; for a network, the 32 threads of a warp evaluate
//    their samples together (the paper's appendix "In-Shader Inference Details"): each thread encodes its
//    point into its row of a shared-memory tile, then the warp runs the MLP on the 32 rows with tensor-core
//    (WMMA) tiles, the weights in shared memory;
//  - sample streaming: ray queues in GPU memory, a coordinate stage (up to K samples per live ray), a scan
//    (CUB) that packs the samples, one batched inference (the training backend's encoding + MLP kernels), a
//    shading stage, and CUB stream compaction of finished rays; one host synchronisation per iteration.
// Macro-cells live on the GPU: value ranges uploaded (or computed from the grid on the GPU), max opacity
// recomputed on the GPU when the transfer function changes.
// Plain C++ API; without CUDA (VNR_CUDA=OFF) every entry point fails with one line.
#include <memory>
#include <vector>
#include "vnr/grid_view.h"
#include "vnr/core/value_range_grid.h"
#include "vnr/render/brick_cache_view.h"
#include "vnr/cuda/cuda.h"
#include "vnr/render/renderer.h"

namespace vnr {

class Network;

// What a GpuRenderer copies to the GPU: the ground-truth grid (grid.data set), a trained network, or
// a brick cache it keeps a copy of (docs/RENDERING.md "Brick cache").
struct GpuFieldSource {
  GridView grid;                     // normalised voxels in host memory
  const Network* network = nullptr;  // else a network (it must outlive the renderer's construction)
  Int3 dims;                         // the field's voxels (the central-difference step of shading)
  const BrickCacheCopySource* cache = nullptr;  // else a brick cache (it must outlive the renderer)
};

class GpuRenderer final : public FrameRenderer {
public:
  // The field's grid or network is copied to the GPU; mc gives the value ranges (the opacities are
  // recomputed on the GPU for tf). fields/fields.h's make_renderer builds one from a field.
  GpuRenderer(const GpuFieldSource& field, Vec3f box, const MacroCells& mc, const TransferFunction& tf, const Camera& cam,
              const RenderOptions& opt, cuda::MlpPath mlp = cuda::MlpPath::Auto);
  ~GpuRenderer() override;
  GpuRenderer(const GpuRenderer&) = delete;
  GpuRenderer& operator=(const GpuRenderer&) = delete;

  void render_frame(uint32_t frame, Image& img, RenderStats* stats = nullptr) override;
  void render_frame_resident(uint32_t frame, RenderStats* stats = nullptr) override;
  void render_mean_rgba8(uint32_t frame, std::vector<uint8_t>& rgba) override;
  void set_camera(const Camera& cam) override;
  Device device() const override { return Device::Cuda; }
  // A network field's new parameters copied in place, device to device from device_half, and mc's ranges
  // uploaded (opacities recomputed); a brick cache's copy takes the ranges (the host cache refreshes its
  // stale bricks, the copy takes them frame by frame); false for a grid field or without device_half.
  bool refresh_network(const MacroCells& mc, const void* device_half) override;

  // A new transfer function: the table is uploaded and every cell's max opacity recomputed on the GPU.
  void set_transfer_function(const TransferFunction& tf);
  // New value ranges (e.g. the online ranges after more training steps); opacities recomputed.
  void set_ranges(const ValueRangeGrid& ranges);
  // The per-cell max opacity the GPU computed (tests compare it with MacroCells::update).
  std::vector<float> max_opacity();
  // The MLP implementation of streaming inference (Fused or Cublas; in-shader always uses WMMA tiles).
  cuda::MlpPath mlp_path() const;
  // Streaming: the most points one batched inference takes (default 4M; more go in further calls), which
  // bounds the network's GPU buffers whatever the image size.
  void set_inference_slab(int64_t points);
  // Whether the in-shader kernel holds the MLP weights in shared memory (else it reads them through L1).
  bool inshader_weights_shared() const;

private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Value ranges of a normalised grid computed on the GPU: value_ranges_from_grid's cells, exactly.
ValueRangeGrid gpu_value_ranges_from_grid(const GridView& g, int cell_size = 16);

}  // namespace vnr
