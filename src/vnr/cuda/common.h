#pragma once
// Internal helpers of the CUDA backend shared by its .cu files: error checks and an owning device buffer
// that counts the bytes the backend holds (peak memory reports).
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <string>

namespace vnr::cuda {

[[noreturn]] void cuda_fail(const char* call, const char* error, const char* file, int line);
[[noreturn]] void cuda_fail_message(const std::string& message);

}  // namespace vnr::cuda

#if defined(__CUDACC__)
#include <cuda_runtime.h>
#include <cublas_v2.h>

#define VNR_CUDA_CHECK(x)                                                              \
  do {                                                                                 \
    cudaError_t err_ = (x);                                                            \
    if (err_ != cudaSuccess) ::vnr::cuda::cuda_fail(#x, cudaGetErrorString(err_), __FILE__, __LINE__); \
  } while (0)
#define VNR_CUBLAS_CHECK(x)                                                            \
  do {                                                                                 \
    cublasStatus_t st_ = (x);                                                          \
    if (st_ != CUBLAS_STATUS_SUCCESS)                                                  \
      ::vnr::cuda::cuda_fail(#x, cublasGetStatusString(st_), __FILE__, __LINE__);      \
  } while (0)
// After a kernel launch: reports bad launch configurations at once (asynchronous faults surface at the
// next synchronising call).
#define VNR_CUDA_LAUNCHED() VNR_CUDA_CHECK(cudaGetLastError())

namespace vnr::cuda {

// Bytes held by every DeviceBuffer now, and the most ever held (process-wide; a brick cache's decoding
// thread allocates beside the frames' thread).
std::atomic<uint64_t>& device_bytes_now();
std::atomic<uint64_t>& device_bytes_peak();

template <typename T>
class DeviceBuffer {
public:
  DeviceBuffer() = default;
  explicit DeviceBuffer(size_t n) { resize(n); }
  ~DeviceBuffer() { release(); }
  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;
  DeviceBuffer(DeviceBuffer&& o) noexcept : p_(o.p_), n_(o.n_) { o.p_ = nullptr; o.n_ = 0; }
  DeviceBuffer& operator=(DeviceBuffer&& o) noexcept {
    if (this != &o) {
      release();
      p_ = o.p_;
      n_ = o.n_;
      o.p_ = nullptr;
      o.n_ = 0;
    }
    return *this;
  }

  void resize(size_t n) {  // contents are not kept
    if (n == n_) return;
    release();
    if (n == 0) return;
    cudaError_t e = cudaMalloc(&p_, n * sizeof(T));
    if (e != cudaSuccess) {
      p_ = nullptr;
      size_t free_b = 0, total_b = 0;
      cudaMemGetInfo(&free_b, &total_b);
      cuda_fail_message("out of GPU memory: " + std::to_string(n * sizeof(T) >> 20) + " MiB asked for, " +
                        std::to_string(free_b >> 20) + " MiB free of " + std::to_string(total_b >> 20) +
                        " MiB (" + cudaGetErrorString(e) + ")");
    }
    n_ = n;
    const uint64_t now = device_bytes_now().fetch_add(n * sizeof(T)) + n * sizeof(T);
    uint64_t peak = device_bytes_peak().load();
    while (now > peak && !device_bytes_peak().compare_exchange_weak(peak, now)) {
    }
  }
  void release() {
    if (p_) {
      cudaFree(p_);
      device_bytes_now().fetch_sub(n_ * sizeof(T));
    }
    p_ = nullptr;
    n_ = 0;
  }
  T* data() { return p_; }
  const T* data() const { return p_; }
  size_t size() const { return n_; }
  void upload(const T* host, size_t n, size_t at = 0) {
    VNR_CUDA_CHECK(cudaMemcpy(p_ + at, host, n * sizeof(T), cudaMemcpyHostToDevice));
  }
  void download(T* host, size_t n, size_t at = 0) const {
    VNR_CUDA_CHECK(cudaMemcpy(host, p_ + at, n * sizeof(T), cudaMemcpyDeviceToHost));
  }
  void zero_async(cudaStream_t s) {
    if (n_) VNR_CUDA_CHECK(cudaMemsetAsync(p_, 0, n_ * sizeof(T), s));
  }

private:
  T* p_ = nullptr;
  size_t n_ = 0;
};

inline unsigned blocks_for(int64_t n, int threads) { return unsigned((n + threads - 1) / threads); }

}  // namespace vnr::cuda
#endif
