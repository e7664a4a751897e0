#pragma once
// The backend a piece of work runs on. The library API takes it explicitly; front ends resolve the
// user's "auto" (cuda when a device is visible) with cuda::resolve_device().
namespace vnr {

enum class Device { Cpu, Cuda };

inline const char* device_name(Device d) { return d == Device::Cuda ? "cuda" : "cpu"; }

}  // namespace vnr
