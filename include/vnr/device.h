#pragma once
// What vnr can run on: the backend a piece of work runs on (the library API takes it explicitly; front
// ends resolve the user's "auto", cuda when a device is visible, with cuda::resolve_device()), the
// CUDA devices and the CPU's SIMD target. Plain C++: callable whether or not vnr was built with CUDA
// (without it, devices() is empty and cuda work fails with one clear line).
#include <cstdint>
#include <string>
#include <vector>

namespace vnr {

enum class Device { Cpu, Cuda };

inline const char* device_name(Device d) { return d == Device::Cuda ? "cuda" : "cpu"; }

namespace kernels {
// The SIMD target the CPU kernels chose at run time (e.g. "AVX3", "AVX2", "SSE4", "EMU128").
const char* simd_target_name();
}  // namespace kernels

namespace cuda {

bool built();  // compiled with the CUDA backend

struct DeviceInfo {
  int index = 0;
  std::string name;
  int cc_major = 0, cc_minor = 0;
  uint64_t memory_bytes = 0;
  int sm_count = 0;
};
// Visible CUDA devices; empty when built without CUDA, with no driver, or with no device.
std::vector<DeviceInfo> devices();
// Why devices() is empty, in words.
std::string no_device_reason();
// Fails with one line (the reason) when there is no device.
void require_device();
// Makes device `slot` modulo the visible devices' count the one this process's CUDA work runs on from now
// on, and returns its index; -1 without a device (nothing changes). An MPI rank passes its rank on the
// node, so that a node's ranks spread over its GPUs instead of all taking the first.
int use_device_for(int slot);
// Free memory of the current device in bytes (0 without one).
uint64_t free_memory_bytes();
// "cpu", "cuda" (fails without a device) or "auto" (cuda when a device is visible, else cpu).
Device resolve_device(const std::string& name);
// One line for --version / vnr info: "cuda (NVIDIA H100 80GB HBM3, sm_90, 79.1 GiB)", "cuda: built, no CUDA
// device (...)" or "cuda: not built".
std::string backend_summary();

// The MLP implementation: the fully fused tensor-core kernels (widths 16/32/64/128, activations and the
// current layer's weights in shared memory), or one cuBLAS GEMM per layer (any width; also the fallback
// when a fused kernel's shared memory does not fit the device).
enum class MlpPath { Auto, Fused, Cublas };
const char* mlp_path_name(MlpPath p);
MlpPath parse_mlp_path(const std::string& s);  // auto | fused | cublas

}  // namespace cuda
}  // namespace vnr
