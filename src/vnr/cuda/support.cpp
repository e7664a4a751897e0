// Parts of the CUDA backend's API that need no CUDA: built with or without the backend.
#include <algorithm>
#include "vnr/error.h"
#include "vnr/cuda/cuda.h"

namespace vnr::cuda {

const char* mlp_path_name(MlpPath p) {
  switch (p) {
    case MlpPath::Auto: return "auto";
    case MlpPath::Fused: return "fused";
    case MlpPath::Cublas: return "cublas";
  }
  return "?";
}

MlpPath parse_mlp_path(const std::string& s) {
  if (s == "auto") return MlpPath::Auto;
  if (s == "fused") return MlpPath::Fused;
  if (s == "cublas") return MlpPath::Cublas;
  fail("unknown MLP path '{}' (allowed: auto, fused, cublas)", s);
}

Device resolve_device(const std::string& name) {
  if (name == "cpu") return Device::Cpu;
  if (name == "cuda") {
    require_device();
    return Device::Cuda;
  }
  if (name == "auto") return devices().empty() ? Device::Cpu : Device::Cuda;
  fail("unknown --device '{}' (allowed: auto, cpu, cuda)", name);
}

std::string backend_summary() {
  if (!built()) return "cuda: not built";
  std::vector<DeviceInfo> ds = devices();
  if (ds.empty()) return "cuda: built, " + no_device_reason();
  std::string s = "cuda:";
  for (const DeviceInfo& d : ds)
    s += fmt::format(" [{}] {} (sm_{}{}, {:.1f} GiB, {} SMs)", d.index, d.name, d.cc_major, d.cc_minor,
                     double(d.memory_bytes) / double(1ull << 30), d.sm_count);
  return s;
}

uint64_t GpuTrainer::bytes_needed(const Network& net, uint64_t voxels, int64_t batch) {
  // Mirrors the trainer's buffers (device_network.cu PassBuffers::allocate, gpu_trainer.cu GpuTrainer::Impl): per sample X0
  // and dX0, hidden activations and their gradients, dOut (half); coordinates, target, output and the
  // cuBLAS path's scratch (binary32). Per parameter: master, gradient, two moments, count, half copy.
  const MlpLayout& m = net.mlp();
  const uint64_t per_sample = 2 * (2 * uint64_t(m.in_pad) + 2 * uint64_t(m.n_hidden) * m.width + m.out_pad) +
                              4 * (4 + uint64_t(m.n_out)) + 4 * uint64_t(std::max(m.in_pad, m.width));
  return voxels * sizeof(float) + uint64_t(batch) * per_sample + net.n_params() * (5 * 4 + 2);
}

std::string unsupported_reason(const Network& net) {
  const ModelConfig& c = net.config();
  if (!net.has_grid())
    return "--device cuda runs grid encodings (HashGrid, DenseGrid, TiledGrid); this model's encoding is not a grid";
  if (c.network.activation != Activation::ReLU)
    return fmt::format("--device cuda runs ReLU hidden layers; this model uses {}",
                       activation_name(c.network.activation));
  if (net.mlp().n_out > 16) return "--device cuda runs models with at most 16 outputs";
  // The grid table follows the MLP's weights in one array and an entry's F features are one vector access
  // (F halves; F floats' atomics): the table must start at a multiple of F. FullyFusedMLP's sizes always do.
  const uint32_t F = net.grid().n_features;
  if (F > 1 && net.mlp().n_params % F != 0)
    return fmt::format("--device cuda runs MLPs whose parameter count is a multiple of the grid's {} features per "
                       "level; this one has {} (a CutlassMLP width that is a multiple of 8 gives one)",
                       F, net.mlp().n_params);
  return "";
}

void check_supported(const Network& net) {
  const std::string why = unsupported_reason(net);
  if (!why.empty()) fail("{}: use --device cpu", why);
}

}  // namespace vnr::cuda
