#pragma once
// Creating a training backend (trainer_backend.h) on an explicitly chosen device, and choosing that
// device for a user's "auto".
#include <memory>
#include <string>
#include "vnr/device.h"
#include "vnr/cuda/cuda.h"
#include "vnr/train/sampler.h"
#include "vnr/train/trainer.h"
#include "vnr/train/trainer_backend.h"
#include "vnr/volume/volume.h"

namespace vnr {

// Device::Cpu: a CpuTrainer drawing from `sampler` (opts as given). Device::Cuda: cuda::GpuTrainer over
// `in_memory` when given (a volume held in memory; the GPU samples it itself, exactly as InCoreSampler
// does), else fed by `sampler` on the host (the CPU trainer's samples: begin_step, then its chunks);
// opts.batch and opts.seed (opts.precision is the CPU's). Both train `net` in place or via download();
// net, sampler and volume must outlive the trainer.
std::unique_ptr<Trainer> make_trainer(Device device, Network& net, std::shared_ptr<Sampler> sampler,
                                      const Volume* in_memory, const TrainOptions& opts,
                                      cuda::MlpPath mlp = cuda::MlpPath::Auto);

// The device of a training run asked for `asked` ("cpu", "cuda" or "auto"): cuda where the run can train
// on the GPU (a network the GPU supports, enough free memory for its state and, when `in_memory`, the
// volume; no reason to stay on the CPU such as live previews: `cpu_only_reason`), else the CPU. A volume
// out of memory is sampled on the host and fed to the GPU. Asking for "cuda" where the run cannot fails
// with the reason ("...; use --device cpu"); "auto" falls back to the CPU and says why in `note`
// ("training on the CPU: <reason>"; empty when nothing needs saying).
struct DeviceChoice {
  Device device = Device::Cpu;
  std::string note;
};
DeviceChoice choose_training_device(const std::string& asked, const Network& net, Int3 dims, bool in_memory,
                                    int64_t batch,
                                    const std::string& cpu_only_reason = "");

}  // namespace vnr
