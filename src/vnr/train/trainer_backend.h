#pragma once
// The training backend: what one training loop (TrainingSession, OnlineLoop) drives, whichever device
// runs the steps. CpuTrainer (trainer.h) and the CUDA trainer (make_trainer(Device::Cuda, ...), a
// wrapper of cuda::GpuTrainer) implement it. The calls are per step or per group of steps, never per
// sample, so a virtual call costs nothing measurable.
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>
#include "vnr/device.h"
#include "vnr/math.h"
#include "vnr/core/value_range_grid.h"
#include "vnr/nn/network.h"
#include "vnr/nn/param_codec.h"

namespace vnr {

class Trainer {
public:
  virtual ~Trainer() = default;
  virtual Device device() const = 0;
  // True when run() only enqueues work (the GPU): callers then group steps between synchronisations.
  virtual bool asynchronous() const { return false; }
  // Runs (GPU: enqueues) n training steps.
  virtual void run(int64_t n_steps) = 0;
  // Waits until the steps run() enqueued are done (a no-op where run() returns with them done).
  virtual void synchronize() {}
  // Mean loss of the last step (0 before any), of every step so far, and of steps first, first + 1, ...
  // so far (a caller that polls asks for the new ones alone: the GPU copies no more); all synchronise.
  virtual float last_loss() const = 0;
  std::vector<float> losses() const { return losses_from(0); }
  virtual std::vector<float> losses_from(uint64_t first) const = 0;
  virtual uint64_t steps_done() const = 0;
  virtual float current_learning_rate() const = 0;  // this step's, the multiplier included
  // Scales the learning rate of the following steps (TrainingSession's cool-down); 1 = the config's.
  virtual void set_learning_rate_multiplier(float m) = 0;
  // Online macro-cells (paper "Macro-Cell Optimization"): from now on every training sample widens the
  // value range of its macro-cells; (re)starts empty.
  virtual void enable_online_ranges(Int3 dims, int cell_size = 16) = 0;
  virtual bool has_online_ranges() const = 0;
  virtual ValueRangeGrid online_ranges() const = 0;
  // Brings the trained parameters back into network().params() (the GPU keeps its own copy; a no-op on
  // the CPU, which trains the Network in place).
  virtual void download() = 0;
  // The half parameters the GPU's steps read, in GPU memory, once the steps so far are done (a GPU
  // renderer of network() copies them device to device); null on the CPU.
  virtual const void* device_half_params() { return nullptr; }
  virtual Network& network() = 0;
  virtual int64_t batch() const = 0;
  virtual uint32_t seed() const = 0;
  // The CPU trainer's MLP arithmetic; nullopt on the GPU (tcnn's own half-precision arithmetic).
  virtual std::optional<Precision> mlp_precision() const = 0;
  // What runs the steps, for a front end's "training on ..." line; empty where nothing needs saying (CPU).
  virtual std::string device_summary() const { return {}; }
  // The GPU's MLP implementation ("fused", "cublas") and the most device memory its buffers held at
  // once, for benchmarks; "" and 0 on the CPU.
  virtual std::string mlp_path_name() const { return {}; }
  virtual uint64_t peak_device_memory_bytes() const { return 0; }
  // Seconds of each phase of the last step (report key, printed name). The GPU records them only while
  // phase timing is on (CUDA events between the phases of every step); the CPU always does.
  struct PhaseTime {
    std::string key, name;
    double seconds = 0;
  };
  virtual void set_phase_timing(bool on) {}
  // Called with the summed gradient (one float per parameter) before each optimizer step, so that a
  // caller can add a term of its own (rate-aware training); an empty function removes it. False when
  // this trainer cannot (the GPU trainer keeps its gradient on the device).
  virtual bool set_gradient_hook(std::function<void(float* grads)> hook) { return !hook; }
  // Quantization-aware steps on the trainer's own copy of the parameters (the GPU trainer keeps them on
  // the device; the CPU trainer's run through the session's step hooks instead, train/rate_control.cpp).
  // From the next step on, each step's forward pass sees `master` quantized with its segment's step
  // (straight-through: the update lands on master); rate_weight_per_loss > 0 adds the rate term's
  // gradient (train/rate_term.h) of the segments from first_rate_segment on, times the last loss.
  virtual bool has_quantized_steps() const { return false; }
  virtual void begin_quantized_steps(const std::vector<float>& master, const std::vector<ParamSegment>& segments,
                                     size_t first_rate_segment, double rate_weight_per_loss) {}
  // Ends them; master receives the master copy as trained.
  virtual void end_quantized_steps(std::vector<float>& master) {}
  virtual std::vector<PhaseTime> last_step_phases() const = 0;
};

}  // namespace vnr
