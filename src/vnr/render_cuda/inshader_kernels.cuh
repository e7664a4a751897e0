#pragma once
// The GPU in-shader kernels (CUDA-only header of gpu_renderer.cu): one thread per pixel runs the shared
// per-pixel loop of render/inshader_loop.h, the same function the CPU renderer calls per pixel; a warp's
// 32 pixels are its lane group (the network evaluation is warp-cooperative: cuda/point_eval.cuh).
#include <cuda_runtime.h>
#include <mutex>
#include "vnr/grid_view.h"
#include "vnr/cuda/point_eval.cuh"
#include "vnr/render/inshader_loop.h"

namespace vnr::gpu_render {

// A block of 4 warps covers 16 x 8 pixels, each warp 8 x 4 (neighbouring rays, neighbouring samples:
// coherent hash-grid reads and few idle lanes).
constexpr int kWarpsPerBlock = 4;
constexpr int kBlockW = 16, kBlockH = 8;
// Blocks per SM the kernels are compiled for (launch bounds, i.e. at most 128 registers a thread): a
// paper-config network's shared memory (74 KiB a block, weights and tiles) holds an H100's SM to 3
// blocks, so those registers cost no occupancy. Left to itself ptxas gave the network kernels 56-64
// registers and spilled 0.5-0.8 KiB a thread (docs/benchmarks.md, "GPU kernels without local memory").
constexpr int kInshaderBlocksPerSm = 4;

// The ground-truth grid as a lane evaluator: every lane looks up its own point.
struct GridWarpField {
  GridView g;
  struct Eval {
    GridView g;
    __device__ bool any(bool active) const { return __any_sync(cuda::kFullWarp, active); }
    __device__ float operator()(bool active, float x, float y, float z) const {
      return active ? grid_lookup(g, x, y, z) : 0.0f;
    }
  };
  __device__ Eval bind(unsigned char*) const { return Eval{g}; }
};

// The pixel of a thread.
__device__ inline bool inshader_pixel(const RenderParams& p, int* ix, int* iy) {
  const int warp = int(threadIdx.x / 32), lane = int(threadIdx.x % 32);
  *ix = int(blockIdx.x) * kBlockW + (warp % 2) * 8 + lane % 8;
  *iy = int(blockIdx.y) * kBlockH + (warp / 2) * 4 + lane / 8;
  return *ix < p.cam.width && *iy < p.cam.height;
}

// The start of every in-shader kernel: the field bound to the block's shared memory and the thread's
// pixel (out-of-image threads stay, inactive: the field evaluation is warp-cooperative).
template <class Field>
struct InshaderThread {
  typename Field::Eval eval;
  int ix, iy;
  bool in_image;
  __device__ InshaderThread(const RenderParams& p, const Field& field, unsigned char* smem)
      : eval(field.bind(smem)) {
    in_image = inshader_pixel(p, &ix, &iy);
  }
  __device__ int64_t pixel(const RenderParams& p) const { return int64_t(iy) * p.cam.width + ix; }
};

__device__ inline void count_samples(int64_t mine, unsigned long long* total) {
  unsigned long long my = (unsigned long long)mine;
  for (int off = 16; off > 0; off /= 2) my += __shfl_down_sync(cuda::kFullWarp, my, off);
  if (threadIdx.x % 32 == 0 && my) atomicAdd(total, my);
}

// In-shader ray marching (shadow = 1: and the single-shot shadow ray), M field points per sample.
template <class Field, int M>
__global__ void __launch_bounds__(kWarpsPerBlock * 32, kInshaderBlocksPerSm)
    inshader_march(RenderParams p, Field field, int shadow, Vec4f* __restrict__ img, unsigned long long* samples) {
  extern __shared__ __align__(128) unsigned char smem[];
  const InshaderThread<Field> t(p, field, smem);
  int64_t my = 0;
  const Vec4f c = inshader_march_pixel<M>(p, t.eval, t.ix, t.iy, t.in_image, shadow != 0, &my);
  if (t.in_image) img[t.pixel(p)] = c;
  count_samples(my, samples);
}

// In-shader path tracing: the sample()/shade() state machine of one path per thread.
template <class Field>
__global__ void __launch_bounds__(kWarpsPerBlock * 32, kInshaderBlocksPerSm)
    inshader_path(RenderParams p, Field field, Vec4f* __restrict__ img, unsigned long long* samples) {
  extern __shared__ __align__(128) unsigned char smem[];
  const InshaderThread<Field> t(p, field, smem);
  int64_t my = 0;
  const Vec4f c = inshader_path_pixel(p, t.eval, t.ix, t.iy, t.in_image, &my);
  if (t.in_image) img[t.pixel(p)] = c;
  count_samples(my, samples);
}

// Lets the network kernels (grids of NF features per level) take `bytes` of dynamic shared memory. The
// attribute is the process's, shared by every renderer of an NF: it only grows, so a renderer made later
// for a smaller network does not take it from one still drawing a larger.
template <int NF>
void allow_inshader_smem(int bytes) {
  static std::mutex mu;
  static int allowed = 0;
  const std::lock_guard<std::mutex> lock(mu);
  if (bytes <= allowed) return;
  using Net = cuda::WarpNetworkRef<NF>;
  VNR_CUDA_CHECK(cudaFuncSetAttribute(inshader_march<Net, 1>, cudaFuncAttributeMaxDynamicSharedMemorySize, bytes));
  VNR_CUDA_CHECK(cudaFuncSetAttribute(inshader_march<Net, 7>, cudaFuncAttributeMaxDynamicSharedMemorySize, bytes));
  VNR_CUDA_CHECK(cudaFuncSetAttribute(inshader_path<Net>, cudaFuncAttributeMaxDynamicSharedMemorySize, bytes));
  allowed = bytes;
}

// Launches the in-shader kernel of `mode` (0 march, 1 shadow, 2 path) over the image on `stream`.
template <class Field>
void launch_inshader(const RenderParams& p, const Field& f, size_t smem, int mode, Vec4f* img,
                     unsigned long long* samples, cudaStream_t stream) {
  const dim3 grid(unsigned((p.cam.width + kBlockW - 1) / kBlockW), unsigned((p.cam.height + kBlockH - 1) / kBlockH));
  const unsigned threads = kWarpsPerBlock * 32;
  if (mode == 2) {
    inshader_path<Field><<<grid, threads, smem, stream>>>(p, f, img, samples);
  } else if (march_points_per_sample(p) == 1) {
    inshader_march<Field, 1><<<grid, threads, smem, stream>>>(p, f, mode, img, samples);
  } else {
    inshader_march<Field, 7><<<grid, threads, smem, stream>>>(p, f, mode, img, samples);
  }
  VNR_CUDA_LAUNCHED();
}

}  // namespace vnr::gpu_render
