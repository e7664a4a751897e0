#pragma once
// The CUDA backend's host API. Plain C++ (no CUDA types), so every layer above can call it whether or
// not vnr was built with CUDA: without it (VNR_CUDA=OFF) devices() is empty and everything else fails
// with one clear line. CI has the toolkit but no GPU or driver: cudaGetDeviceCount then returns an
// error, which means "no device", never a failure.
//
// Semantics are tiny-cuda-nn's (docs/semantics.md): half weights and activations, binary32 accumulation, loss
// scale 128 on the half gradients, Adam on a binary32 master copy with the zero-gradient skip of grid
// parameters. The per-sample code (sampling, trilinear targets, grid corners, losses) is the same
// VNR_HD source the CPU runs; only the hot kernels (grid gather/scatter, the MLP, Adam) are CUDA's own.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>
#include "vnr/device.h"
#include "vnr/math.h"
#include "vnr/core/value_range_grid.h"
#include "vnr/nn/network.h"
#include "vnr/nn/param_codec.h"
#include "vnr/volume/volume.h"

namespace vnr::cuda {

// built(), devices(), resolve_device(), MlpPath ...: vnr/device.h (public).

// Why the network cannot run on the GPU (it needs a grid encoding, ReLU hidden layers, at most 16
// outputs); empty when it can. check_supported fails with that line.
std::string unsupported_reason(const Network& net);
void check_supported(const Network& net);

struct GpuTrainOptions {
  int64_t batch = 65536;  // samples per step, a multiple of 256
  uint32_t seed = 1337;   // sampling seed (initialisation is the Network's)
  int chunk = 256;        // the CPU trainer's chunk: samples are drawn per (step, chunk) exactly as on the CPU
  MlpPath mlp = MlpPath::Auto;
};

// A step's training samples drawn on the host, for a GpuTrainer that does not hold the volume (the
// out-of-core sampler, a time series' switching target): fill() writes the batch of step `step`
// (coordinates SoA and normalised targets, `batch` values each). It runs on the thread that calls
// run(), while the GPU still works on the previous step.
class HostBatchSource {
public:
  virtual ~HostBatchSource() = default;
  virtual void fill(uint64_t step, int64_t batch, float* x, float* y, float* z, float* target) = 0;
};

// Trains a Network on the GPU: from a normalised volume held in GPU memory (the in-core sampler of
// docs/semantics.md B.3, bit-identical coordinates and targets to the CPU's for the same seed and chunk),
// or from batches a HostBatchSource draws on the host (copied through two pinned staging buffers, so
// drawing step k+1 overlaps the GPU's step k).
class GpuTrainer {
public:
  GpuTrainer(Network& net, GridView volume, GpuTrainOptions opts);
  GpuTrainer(Network& net, std::shared_ptr<HostBatchSource> source, GpuTrainOptions opts);
  ~GpuTrainer();
  // GPU memory a trainer needs for this network, volume and batch (the constructor refuses to start
  // with less free): the volume, the per-sample buffers of a step, the per-parameter optimizer state.
  static uint64_t bytes_needed(const Network& net, uint64_t voxels, int64_t batch);
  GpuTrainer(const GpuTrainer&) = delete;
  GpuTrainer& operator=(const GpuTrainer&) = delete;

  // Enqueues n training steps; no host synchronisation (the learning-rate schedule is host arithmetic).
  void run(int n_steps);
  void synchronize();
  // Mean loss of steps first, first + 1, ... so far, and of the last one (both synchronise).
  std::vector<float> losses(uint64_t first = 0);
  float last_loss();
  uint64_t steps_done() const;
  float current_learning_rate() const;
  void set_learning_rate_multiplier(float m);  // scales the following steps' learning rate
  // Online macro-cells (paper "Macro-Cell Optimization"): from now on every batch widens the value
  // ranges of the cells around its samples, on the GPU (the CpuTrainer's cells, exactly).
  void enable_online_ranges(Int3 dims, int cell_size = 16);
  bool has_online_ranges() const;
  ValueRangeGrid online_ranges();  // synchronises
  // Copies the binary32 master parameters back into the Network (and refreshes its half grid).
  void download();
  // The half parameters the steps read (MLP then grid, the Network's order; quantized during quantized
  // steps), in GPU memory, after the enqueued steps (synchronises): what a GPU renderer of the same
  // network copies device to device instead of going through the host.
  const void* device_half_params();
  // Quantization-aware steps (Trainer::begin_quantized_steps): the master copy becomes `master`, and
  // until end_quantized the half parameters every step reads are quantized_value(master, step of its
  // segment) (nn/quantization_hd.h); rate_weight_per_loss > 0 adds the rate term of the segments from
  // first_rate_segment on to the gradient, scaled by the previous step's loss, read on the device.
  void begin_quantized(const std::vector<float>& master, const std::vector<ParamSegment>& segments,
                       size_t first_rate_segment, double rate_weight_per_loss);
  // Ends them (synchronises): master receives the master copy; the half parameters are its fp16 again.
  void end_quantized(std::vector<float>& master);
  MlpPath mlp_path() const;
  // Most bytes of GPU memory the backend's buffers held at once (the volume included; cuBLAS's own
  // workspace not).
  uint64_t peak_memory_bytes() const;
  // With profiling on, every step records CUDA events between its phases; phase_seconds() then gives
  // the last step's {sampling + encoding, MLP forward + loss + backward, grid backward, Adam} (synchronises).
  void set_profiling(bool on);
  std::vector<double> phase_seconds();

private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// A Network resident on the GPU, for batched queries. Inputs and outputs are host arrays; work is
// streamed through the GPU in slabs, so outputs of any size fit.
class GpuNetwork {
public:
  explicit GpuNetwork(const Network& net, MlpPath mlp = MlpPath::Auto);
  ~GpuNetwork();
  GpuNetwork(const GpuNetwork&) = delete;
  GpuNetwork& operator=(const GpuNetwork&) = delete;

  // out[i] = first network output (after the output activation) at coords[3i..3i+2].
  void infer(const float* coords, int64_t n, float* out);
  // New parameters of the same network, copied device to device from device_half (a trainer's half
  // parameters in GPU memory, the Network's order).
  void reload_params(const void* device_half);
  // decode_slices() of model_io on the GPU: voxel centres ((i + 0.5) / n per axis, the same expressions)
  // of slices [z0, z1) of a dims-sized grid, x fastest.
  void decode_slices(Int3 dims, int64_t z0, int64_t z1, float* out);
  // Samples per slab (default 4M); for tests and memory limits.
  void set_slab(int64_t samples);
  MlpPath mlp_path() const;
  uint64_t peak_memory_bytes() const;
  // Throughput with everything resident on the GPU (no transfers): n random points, encoding + MLP,
  // timed with CUDA events over `repeats` batches. Seconds per batch, total and MLP alone.
  struct ResidentTiming {
    double seconds = 0, mlp_seconds = 0;
  };
  ResidentTiming time_resident(int64_t n, int repeats);

private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Kernel-level entry points for the gpu tests: each runs one kernel family on the GPU for n points
// (interleaved xyz) and returns host arrays, so tests compare them with the CPU reference.
namespace testing {
// The padded encoding, sample-major: n x in_pad values (rounded to half, as the MLP reads them).
std::vector<float> encode(const Network& net, const float* coords, int n);
// The unscaled loss gradient of every parameter (tcnn order) for one batch with the given targets, and
// the batch's mean loss; grads are binary32 (the half working copy drives forward and backward).
std::vector<float> gradient(const Network& net, const float* coords, const float* targets, int n, MlpPath mlp,
                            float* loss);
}  // namespace testing

}  // namespace vnr::cuda
