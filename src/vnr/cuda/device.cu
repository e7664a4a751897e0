// Device query, memory accounting and the stream/cuBLAS pair of every GPU object.
#include <algorithm>
#include <cfloat>
#include <cmath>
#include <vector>
#include "vnr/core/rng.h"
#include "vnr/cuda/cuda.h"
#include "vnr/cuda/kernels.cuh"
#include "vnr/cuda/mlp.cuh"
#include "vnr/cuda/network.cuh"
#include "vnr/nn/optimizer.h"


namespace vnr::cuda {

std::atomic<uint64_t>& device_bytes_now() {
  static std::atomic<uint64_t> b{0};
  return b;
}
std::atomic<uint64_t>& device_bytes_peak() {
  static std::atomic<uint64_t> b{0};
  return b;
}

bool built() { return true; }

std::vector<DeviceInfo> devices() {
  int n = 0;
  if (cudaGetDeviceCount(&n) != cudaSuccess) {
    cudaGetLastError();  // clear: no driver or no device is not an error of later calls
    return {};
  }
  std::vector<DeviceInfo> out;
  for (int i = 0; i < n; ++i) {
    cudaDeviceProp p;
    if (cudaGetDeviceProperties(&p, i) != cudaSuccess) continue;
    out.push_back(DeviceInfo{i, p.name, p.major, p.minor, uint64_t(p.totalGlobalMem), p.multiProcessorCount});
  }
  return out;
}

std::string no_device_reason() {
  int n = 0;
  cudaError_t e = cudaGetDeviceCount(&n);
  if (e != cudaSuccess) {
    cudaGetLastError();
    return std::string("no CUDA device (") + cudaGetErrorString(e) + ")";
  }
  return n == 0 ? "no CUDA device" : "";
}

int use_device_for(int slot) {
  int n = 0;
  if (cudaGetDeviceCount(&n) != cudaSuccess || n == 0) {
    cudaGetLastError();
    return -1;
  }
  const int d = (slot % n + n) % n;
  VNR_CUDA_CHECK(cudaSetDevice(d));
  return d;
}

uint64_t free_memory_bytes() {
  if (devices().empty()) return 0;
  size_t free_b = 0, total_b = 0;
  if (cudaMemGetInfo(&free_b, &total_b) != cudaSuccess) {
    cudaGetLastError();
    return 0;
  }
  return free_b;
}

void require_device() {
  if (devices().empty()) cuda_fail_message("--device cuda: " + no_device_reason());
}

StreamAndBlas::StreamAndBlas() {
  require_device();
  VNR_CUDA_CHECK(cudaStreamCreate(&stream));
  VNR_CUDA_CHECK(cudaStreamCreate(&side));
  VNR_CUDA_CHECK(cudaEventCreateWithFlags(&forked, cudaEventDisableTiming));
  VNR_CUDA_CHECK(cudaEventCreateWithFlags(&joined, cudaEventDisableTiming));
  VNR_CUBLAS_CHECK(cublasCreate(&blas));
  VNR_CUBLAS_CHECK(cublasSetStream(blas, stream));
}
StreamAndBlas::~StreamAndBlas() {
  if (blas) cublasDestroy(blas);
  if (joined) cudaEventDestroy(joined);
  if (forked) cudaEventDestroy(forked);
  if (side) cudaStreamDestroy(side);
  if (stream) cudaStreamDestroy(stream);
}
void StreamAndBlas::fork() const {
  VNR_CUDA_CHECK(cudaEventRecord(forked, stream));
  VNR_CUDA_CHECK(cudaStreamWaitEvent(side, forked, 0));
}
void StreamAndBlas::join() const {
  VNR_CUDA_CHECK(cudaEventRecord(joined, side));
  VNR_CUDA_CHECK(cudaStreamWaitEvent(stream, joined, 0));
}

}  // namespace vnr::cuda
