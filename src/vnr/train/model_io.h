#pragma once
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include "vnr/core/device.h"
#include "vnr/cuda/cuda.h"
#include "vnr/nn/model_file.h"
#include "vnr/nn/network.h"
#include "vnr/volume/value_range_grid.h"
#include "vnr/volume/volume.h"

namespace vnr {

// A network together with what it represents: the bridge between the in-memory Network and the
// model files.
struct Model {
  std::unique_ptr<Network> net;
  Int3 dims;
  DType source_dtype = DType::Float32;
  double lo = 0, hi = 1;
  Json training;  // summary written by `vnr train`
  std::optional<ValueRangeGrid> macrocells;  // value ranges built online while training (or imported)
  uint64_t param_bytes() const { return net->n_params() * 2; }  // fp16, as stored
};

// Writes .vnr, or instantvnr's BSON when the path ends in .bson or .json (instantvnr names its
// BSON files params.json).
void save_model(const std::string& path, const Model& m);
Model load_model(const std::string& path);
bool is_instantvnr_path(const std::string& path);

// Evaluation against the ground truth at voxel centres (compat.md B.4).
struct EvalResult {
  double psnr = 0, ssim = 0, mse = 0;
  double max_abs_error = 0;           // normalised units
  double max_abs_error_original = 0;  // original units
  double decode_seconds = 0;
};
EvalResult evaluate(const Network& net, const Volume& vol, bool with_ssim = true, Device device = Device::Cpu);

// Decodes a network at voxel centres ((i + 0.5) / n per axis) on one backend; a GPU decoder keeps its
// copy of the network between calls. On the GPU the network runs in half precision (tcnn's inference),
// so values differ from the CPU's by about 1e-3 relative.
class Decoder {
public:
  Decoder(const Network& net, Device device);
  ~Decoder();
  // z-slices [z0, z1) of `dims` into out (normalised units), x fastest.
  void slices(Int3 dims, int64_t z0, int64_t z1, float* out);
  // n voxels given by index (x + dims.x * (y + dims.y * z)): bit-identical to what slices() gives them.
  void voxels(Int3 dims, const int64_t* voxel_index, int64_t n, float* out);
  Device device() const { return device_; }

private:
  const Network& net_;
  Device device_;
  std::unique_ptr<cuda::GpuNetwork> gpu_;
};

// Decoder(net, Device::Cpu).slices / .voxels.
void decode_slices(const Network& net, Int3 dims, int64_t z0, int64_t z1, float* out);
void decode_voxels(const Network& net, Int3 dims, const int64_t* voxel_index, int64_t n, float* out);

// Whether the model file records the value range of the volume it was trained on: .vnr files do,
// instantvnr BSON files do not (load_model then gives [0, 1]). Reads only the file's first bytes.
bool model_file_has_value_range(const std::string& path);

// evaluate() for a volume that is not in memory: the volume (desc, normalised with [lo, hi] as
// load_volume would) is streamed in z-slabs of about slab_voxels voxels (0: 16 M voxels, i.e.
// 64 MiB per copy; at least one slice) and the network is decoded slab by slab. Memory: two
// slab-sized float arrays (the volume as read, the network's values); with SSIM a third, and
// 6 slices of overlap. PSNR, MSE and max error match evaluate() on the loaded volume up to the
// order of a double sum; the SSIM is the same mean over every 7x7x7 window (windows crossing a
// slab boundary see the 6 slices before it), equal to ssim3d's up to rounding (~1e-14).
// `progress` gets the fraction of slices done.
EvalResult evaluate_streamed(const Network& net, const VolumeDesc& desc, double lo, double hi,
                             const LoadOptions& opts, bool with_ssim = true,
                             const std::function<void(double fraction)>& progress = {}, int64_t slab_voxels = 0,
                             Device device = Device::Cpu);

// PSNR estimated from n_samples voxels drawn uniformly (with replacement; deterministic for a
// seed), read with RawVolumeFile (uncompressed data only) and decoded as evaluate() decodes them.
// The 95% interval is the normal interval mean +- 1.96 standard errors of the per-voxel squared
// error, mapped through PSNR = 10 log10(1/MSE) (an interval end at MSE <= 0 is reported as 999).
// Memory: O(min(n_samples, 1 M)).
struct SampledEval {
  double psnr = 0;                        // from the sampled MSE
  double psnr_ci95_lo = 0, psnr_ci95_hi = 0;
  double mse = 0, mse_stderr = 0;         // normalised units
  double max_abs_error = 0;               // largest error among the samples, normalised units
  double max_abs_error_original = 0;      // the same in original units
  int64_t samples = 0;
  double decode_seconds = 0;
};
SampledEval evaluate_sampled(const Network& net, const VolumeDesc& desc, double lo, double hi, int64_t n_samples,
                             uint64_t seed, const LoadOptions& opts = {}, Device device = Device::Cpu);

// Sizes the grid of `config` (log2_hashmap_size, and n_levels if needed) so the fp16 model is about
// volume_bytes / ratio. Returns the adjusted config; `note` describes the choice.
ModelConfig size_config_for_ratio(const ModelConfig& config, uint64_t volume_bytes, double ratio, std::string* note);

}  // namespace vnr
