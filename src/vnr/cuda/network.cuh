#pragma once
// The CUDA backend's device-side API for the GPU layers above it (rendering), CUDA-only: a stream with
// its cuBLAS handle, forward/backward pass buffers, and a Network resident on the GPU with its batched
// forward pass over coordinates already in GPU memory.
#include <cublas_v2.h>
#include <cuda_fp16.h>
#include <cuda_runtime.h>
#include "vnr/cuda/common.h"
#include "vnr/cuda/kernels.cuh"
#include "vnr/cuda/mlp.cuh"

namespace vnr::cuda {

inline int64_t round_up(int64_t v, int64_t m) { return (v + m - 1) / m * m; }

// One CUDA stream and cuBLAS handle per GPU object, and a side stream for work that runs beside the
// stream's own (fork, then join: both stay ordered on `stream`). The streams are blocking: ordered after
// the synchronous copies and memsets (legacy default stream) that upload volumes, parameters and coordinates.
struct StreamAndBlas {
  cudaStream_t stream = nullptr;
  cublasHandle_t blas = nullptr;
  cudaStream_t side = nullptr;
  cudaEvent_t forked = nullptr, joined = nullptr;
  void fork() const;  // what is queued on `side` from now on runs after what `stream` has queued so far
  void join() const;  // what is queued on `stream` from now on runs after what `side` has queued so far
  StreamAndBlas();
  ~StreamAndBlas();
  StreamAndBlas(const StreamAndBlas&) = delete;
  StreamAndBlas& operator=(const StreamAndBlas&) = delete;
};

// Buffers of one forward (and, training, backward) pass over n samples.
struct PassBuffers {
  DeviceBuffer<__half> X0, acts, dOut, dY, dX0;
  DeviceBuffer<float> out, tmp;
  void allocate(const MlpDims& d, int64_t n, bool training, MlpPath path);
};

// A Network's half working copy (MLP weights, then the grid table; tcnn order) on the GPU, for batched
// inference on coordinates in GPU memory. The Network must outlive it.
class DeviceNetwork {
public:
  DeviceNetwork(const Network& net, MlpPath asked);
  const Network& network() const { return net_; }
  const MlpDims& dims() const { return d_; }
  MlpPath path() const { return path_; }
  const __half* half_params() const { return half_.data(); }
  // New parameters of the same network, in place (the buffers, and pointers into them, stay), copied
  // from device_half: half parameters in GPU memory in the Network's order (a trainer's).
  void reload_params(const void* device_half);
  // The outputs (n x n_out binary32, after the output activation) of n points (interleaved xyz in GPU
  // memory, n a multiple of 16), computed on sb's stream; valid until the next call. after_encoding, if
  // given, is recorded between the encoding and the MLP (timings).
  const float* infer(const float* xyz, int64_t n, const StreamAndBlas& sb, cudaEvent_t after_encoding = nullptr);

private:
  const Network& net_;
  MlpDims d_;
  MlpPath path_;
  GridKernels grid_kernels_;  // for the grid's features per level, chosen once
  DeviceBuffer<__half> half_;
  PassBuffers pass_;
  int64_t allocated_ = 0;
};

// The network's parameters as the half working copy (tcnn order), uploaded.
void upload_half_params(const Network& net, DeviceBuffer<__half>& half);

}  // namespace vnr::cuda
