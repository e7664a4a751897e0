#pragma once
// The CUDA backend's per-sample kernels (CUDA-only header): grid encoding forward/backward, the in-core
// sampler, the loss and Adam. The work inside each thread is the VNR_HD code the CPU runs.
#include <cuda_fp16.h>
#include <cuda_runtime.h>
#include "vnr/core/value_range_grid.h"
#include "vnr/cuda/common.h"
#include "vnr/cuda/mlp.cuh"
#include "vnr/nn/adam_update.h"
#include "vnr/nn/grid_encoding.h"
#include "vnr/volume/volume.h"

namespace vnr::cuda {

// Points as three strided float arrays: point i is (x[i*stride], y[i*stride], z[i*stride]).
struct Coords {
  const float *x, *y, *z;
  int stride;
};
inline Coords interleaved(const float* xyz) { return Coords{xyz, xyz + 1, xyz + 2, 3}; }

// The grid's kernels for its features per level, chosen once (grid_kernels) where a DeviceNetwork or a
// training run is made, not per launch.
struct GridKernels {
  // X0 (n x in_pad half, sample-major) = the grid encoding of n points from the half table; pad columns 0.
  void (*encode)(const GridLayout& g, const __half* table, Coords c, int64_t n, int in_pad, __half* X0,
                 cudaStream_t s) = nullptr;
  // grad (binary32, the grid block) += dL/dtheta for n points, dX0 the loss-scaled half dL/dX0. Atomic adds:
  // correct under hash collisions and between levels.
  void (*backward)(const GridLayout& g, Coords c, int64_t n, int in_pad, const __half* dX0, float* grad,
                   cudaStream_t s) = nullptr;
};
GridKernels grid_kernels(const GridLayout& g);
// Uniform coordinates of docs/semantics.md B.3 (bit-identical to the CPU's for the same seed/step/chunk) and their
// cell-centred trilinear targets from the volume in GPU memory.
void sample_in_core(GridView volume, uint64_t seed, uint64_t step, int chunk, int64_t batch, float* x, float* y,
                    float* z, float* target, cudaStream_t s);
// dOut (n x out_pad half) = S * dL/d(output pre-activation); *loss_slot += the batch's mean loss.
void loss_and_grad(LossType t, Activation out_act, const float* out_pre, const float* target, int64_t n, int n_out,
                   int out_pad, float inv_n, __half* dOut, float* loss_slot, cudaStream_t s);

struct AdamArgs : AdamHyper {
  int matrix;  // 1: l2 applies, never skipped; 0: skipped where the gradient is exactly 0
};
// docs/semantics.md A.7.1 on [0, n): reads and zeroes grads, updates w/m/v/c and writes half(w).
void adam(const AdamArgs& a, float* w, float* grads, float* m, float* v, uint32_t* c, __half* half_out, int64_t n,
          const float* bias_sqrt, const float* bias_den, cudaStream_t s);
// Voxel centres of slices [z0, z0 + count / (nx*ny)) as interleaved xyz, the first `count` points then
// copies of the last up to `padded`.
void voxel_centres(Int3 dims, int64_t first, int64_t count, int64_t padded, float* xyz, cudaStream_t s);

// Macro-cell value ranges (docs/semantics.md B.6) in GPU memory, the cells of a ValueRangeGrid (x fastest); empty
// cells hold lo = +inf, hi = -inf.
struct RangeGridDims {
  int32_t nx = 0, ny = 0, nz = 0;  // cells
  int32_t cell_size = 16;          // voxels per cell per axis
  float sx = 1, sy = 1, sz = 1;    // volume dims: world position = u * dims
};
RangeGridDims range_grid_dims(const ValueRangeGrid& g);
// lo/hi of every cell of a grid in GPU memory: value_ranges_from_grid's reduction (cell_value_range).
void ranges_from_grid(GridView volume, const RangeGridDims& r, float* lo, float* hi, cudaStream_t s);
// Widens the cells around n samples (normalised coordinates, values): the online ranges of training
// batches (ValueRangeGrid::add's cells), by atomic min/max, so the result is the CPU's exactly.
void ranges_add_samples(const RangeGridDims& r, const float* x, const float* y, const float* z, const float* v,
                        int64_t n, float* lo, float* hi, cudaStream_t s);
// lo = +inf, hi = -inf in every cell.
void ranges_clear(const RangeGridDims& r, float* lo, float* hi, cudaStream_t s);

}  // namespace vnr::cuda
