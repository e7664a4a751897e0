#pragma once
// vnr::Model: a network together with the volume it represents (dims, source dtype, value range), its files
// (.vnr, or instantvnr's BSON for .bson/.json), creating one, queries and decodes on an explicit device, the
// compression ratio and evaluation against a Volume or a volume file. The network, macro-cells, residuals
// and bricks are internal types this header only names; the library's functions below are their face.
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>
#include "vnr/device.h"
#include "vnr/dtype.h"
#include "vnr/json.h"
#include "vnr/math.h"
#include "vnr/model_config.h"
#include "vnr/opaque.h"
#include "vnr/volume.h"

namespace vnr {

class Network;          // nn/network.h
struct ValueRangeGrid;  // core/value_range_grid.h
struct Residuals;       // train/residuals.h
struct ParamSegment;    // nn/param_codec.h
struct BrickedModel;    // train/bricks.h
namespace cuda {
class GpuNetwork;  // cuda/cuda.h
}

// A network together with what it represents: the bridge between the in-memory network and the model files.
struct Model {
  Model();
  ~Model();
  Model(Model&&) noexcept;
  Model& operator=(Model&&) noexcept;

  std::unique_ptr<Network> net;
  Int3 dims;
  DType source_dtype = DType::Float32;
  double lo = 0, hi = 1;
  Json training;  // summary written by `vnr train`
  Opaque<ValueRangeGrid> macrocells;  // value ranges built online while training (or imported)
  // Error-bound residuals at dims: decodes at dims apply them on the CPU reference.
  Opaque<Residuals> residuals;
  // Quantization steps of compact storage; empty = plain fp16. The network's parameters are then already
  // the dequantized values, so the file holds them exactly.
  std::vector<ParamSegment> param_segments;
  // A multi-brick model (a directory written by `vnr train --bricks`): net is then a copy of brick 0's
  // network (config, precision); queries, decodes, evaluation and rendering go through the bricks.
  std::shared_ptr<BrickedModel> bricks;
  // What a single network and a multi-brick model answer alike, so that callers need not ask which it is:
  // parameters (all bricks'), their fp16 bytes as stored, and whether a session can train it (a multi-brick
  // model is trained brick by brick).
  uint64_t n_params() const;
  uint64_t param_bytes() const { return n_params() * 2; }
  bool trainable() const;
};

// Writes .vnr, or instantvnr's BSON when the path ends in .bson or .json (instantvnr names its BSON files
// params.json). A multi-brick model is refused (it is a directory of brick files).
void save_model(const std::string& path, const Model& m);
// A .vnr or BSON file, or a multi-brick model's directory.
Model load_model(const std::string& path);
bool is_instantvnr_path(const std::string& path);
// The size of the .vnr file save_model writes for a single-network model, without writing it.
uint64_t model_file_bytes(const Model& m);
// Whether the model file records the value range of the volume it was trained on: .vnr files do,
// instantvnr BSON files do not (load_model then gives [0, 1]). Reads only the file's first bytes.
bool model_file_has_value_range(const std::string& path);

// A fresh model of `config` for a volume of dims voxels of source_dtype with value range [lo, hi] in
// original units, its parameters initialised from `seed` (tcnn's initialisation); or for `volume` (its dims,
// source dtype and value range).
Model create_model(const ModelConfig& config, Int3 dims, DType source_dtype, double lo, double hi, uint32_t seed = 1337);
Model create_model(const ModelConfig& config, const Volume& volume, uint32_t seed = 1337);
// Rounds the network's parameters to what a model file stores (fp16): decodes then equal those of the
// file save_model writes, and saving and loading it is lossless.
void round_params_to_stored(Model& m);

// The network's configuration, and the arithmetic of its CPU inference (Network::set_inference_precision),
// for a single network and a multi-brick model alike (whose bricks share brick 0's configuration and
// decode at the model's precision).
const ModelConfig& model_config(const Model& m);
void set_inference_precision(Model& m, Precision precision);
Precision inference_precision(const Model& m);

// What `vnr info --json` shows of the model loaded from `path` (a file or a multi-brick directory): file,
// format, dims, dtype, value_range, n_params (n_mlp_params, n_grid_params), model_bytes (the file's size),
// volume_bytes, compression_ratio, config, training, macrocells (cell_size, cells, occupied; null when none),
// error_bound (max_error, residual_nonzero, residual_bytes, codec; error-bound models only) and, for a
// multi-brick model, format "vnr-bricks", the parameters summed over the bricks and bricks (grid, ghost,
// seed, count, list). The entries of the grid encoding's table (0 without one): hash_grid_entries.
Json describe_model(const Model& m, const std::string& path);
uint64_t hash_grid_entries(const Model& m);

// Evaluation against the ground truth at voxel centres (docs/semantics.md B.4).
struct EvalResult {
  double psnr = 0, ssim = 0, mse = 0;
  double max_abs_error = 0;           // normalised units
  double max_abs_error_original = 0;  // original units
  double decode_seconds = 0;
};

// The sums behind an evaluation of part of a volume: parts evaluated apart (MPI ranks' slices) add up
// to the evaluation of the whole.
struct EvalSums {
  double sse = 0;            // squared errors summed, normalised units
  int64_t voxels = 0;        // voxels summed
  double max_abs_error = 0;  // normalised units
  double ssim_sum = 0;       // SSIM of every 7x7x7 window summed (ssim3d's windows), and their number
  int64_t ssim_windows = 0;
  double decode_seconds = 0;
  void add(const EvalSums& other);
  // PSNR, MSE, max error (also times value_range, in original units), SSIM (0 without windows).
  EvalResult result(double value_range) const;
};

// Bytes of the source volume: dims x the source dtype's size.
uint64_t source_bytes(const Model& m);
// source_bytes / model_bytes, where model_bytes = 0 means the fp16 parameters (Model::param_bytes(); a
// model file adds a small header: pass its size to get what `vnr info` reports).
double compression_ratio(const Model& m, uint64_t model_bytes = 0);

// Units of query and decode results: normalised [0, 1], or the model's original units lo + u (hi - lo).
enum class ValueUnits { Normalised, Original };
inline float to_original_units(const Model& m, float u) { return float(m.lo + double(u) * (m.hi - m.lo)); }

// Queries and decodes of one model on one device, chosen explicitly. On the GPU the network is copied
// once, at construction, and runs in half precision (values differ from the CPU's by ~1e-3 relative);
// on the CPU it infers with the network's inference precision (Network::set_inference_precision).
// The model must outlive this object and not change while it lives.
// Throws, naming dims and bytes, unless `slices` z-slices of a dims grid (float32, dims.x * dims.y *
// slices voxels) fit the memory available: what a decode checks before allocating its output.
void check_decode_fits_memory(Int3 dims, int64_t slices);

// Fails naming the first point of n (interleaved x, y, z; numbered from `first`) that is not finite and
// in [0, 1]^3: the check of points a user gives (Python's Model.sample), one pass on every core.
void check_unit_points(const float* xyz, int64_t n, int64_t first = 0);

class Decoder;  // train/decoder.h

class ModelQuery {
public:
  ModelQuery(const Model& model, Device device, cuda::MlpPath mlp = cuda::MlpPath::Auto);
  ~ModelQuery();
  ModelQuery(const ModelQuery&) = delete;
  ModelQuery& operator=(const ModelQuery&) = delete;

  // n points, interleaved x, y, z in normalised coordinates [0, 1)^3 -> out[0..n).
  void points(const float* xyz, int64_t n, float* out, ValueUnits units = ValueUnits::Normalised);
  // z-slices [z0, z1) of a grid of dims voxels, sampled at voxel centres ((i + 0.5) / n per axis), x
  // fastest -> out[0 .. dims.x * dims.y * (z1 - z0)): the same z-range of decode(dims), bit for bit.
  // A model with error-bound residuals decodes at its own dims on the CPU reference plus the residuals,
  // whatever the device (train/decoder.h), so every voxel is within the bound.
  void slab(Int3 dims, int64_t z0, int64_t z1, float* out, ValueUnits units = ValueUnits::Normalised);
  // The whole grid at dims (zero dims: the model's own) as a Volume with the model's range and dtype.
  // Refused with the sizes, before allocating, when it cannot fit the memory (check_decode_fits_memory).
  Volume decode(Int3 dims = {});
  // The grid at dims in original units, z-slab by z-slab of about 16 M voxels (memory bounded at any
  // size; refused with the sizes when even a slab cannot fit): sink(z0, z1, values) for each, x fastest.
  void for_each_slab(Int3 dims, const std::function<void(int64_t z0, int64_t z1, const float* values)>& sink);
  // What `vnr decode` writes: the grid at dims (zero dims: the model's own) in original units, stored as
  // dtype (integers rounded to nearest and clamped), in a volume file (OUT.raw with its OUT.json
  // sidecar, or OUT.nrrd) written atomically, in z-slabs of about 16 M voxels: memory stays bounded at
  // any size. progress(slices done, slices in all) after each slab.
  void decode_to_file(const std::string& path, Int3 dims, DType dtype,
                      const std::function<void(int64_t, int64_t)>& progress = {});

  Device device() const { return device_; }
  const Model& model() const { return model_; }
  // The GPU copy of a single network (null on the CPU): what GPU benchmarks time resident.
  cuda::GpuNetwork* gpu();

private:
  const Model& model_;
  Device device_;
  std::unique_ptr<Decoder> decoder_;  // single network or bricks: the one place that tells them apart
};

// PSNR, SSIM (3-D, optional) and max error of the model decoded at the volume's voxel centres against
// the volume (docs/semantics.md B.4), on the given device.
EvalResult evaluate_model(const Model& model, const Volume& volume, bool with_ssim = true, Device device = Device::Cpu);

// Evaluation against a volume file of any size, as `vnr eval` runs it: in memory (Full) when the volume
// and its decoded copy, 8 bytes a voxel, fit the memory budget, else in streamed z-slabs (Streamed); or
// estimated from randomly sampled voxels (Sampled: PSNR with a 95% interval, no SSIM).
enum class EvalMethod { Full, Streamed, Sampled };
const char* eval_method_name(EvalMethod m);  // "full", "streamed", "sampled"
struct FileEvalPlan {
  VolumeDesc desc;
  EvalMethod method = EvalMethod::Full;
  uint64_t full_bytes = 0;   // the volume and the decoded copy in memory
  uint64_t budget = 0;       // the memory budget it was planned for
  int64_t slab_slices = 0;   // Streamed: z-slices per slab
};
// samples > 0 asks for Sampled; no memory_budget = half the available memory. Streamed slabs hold the slab
// as read and decoded (with SSIM also a copy with the 6 slices of window overlap) within the budget, at
// most 16 M voxels and at least one slice.
FileEvalPlan plan_file_evaluation(const VolumeDesc& desc, int64_t samples, bool with_ssim,
                                  std::optional<uint64_t> memory_budget = {});
// The value range a Streamed or Sampled evaluation normalises the volume with (it never holds the
// volume): an explicit one (range overrides, sidecar) as load_volume would use it ("volume"), else the
// range the model was trained with when its file records one ("model"), else one scan of the volume
// ("scan", reporting progress). *source gets the quoted word.
ValueRange file_evaluation_range(const FileEvalPlan& plan, const Model& model, bool model_file_records_range,
                                 const LoadOptions& load, std::string* source,
                                 const std::function<void(double fraction)>& progress = {});

// A whole `vnr eval`: plan_file_evaluation, file_evaluation_range where the method needs it, then the
// method on the device. How to read the volume and what to compute:
struct FileEvalOptions {
  Device device = Device::Cpu;  // resolved; the GPU's support of the network is checked before any read
  bool with_ssim = true;        // Full and Streamed
  int64_t samples = 0;          // > 0: Sampled, from this many random voxels (seeded by seed)
  uint64_t seed = 0;
  std::optional<uint64_t> memory_budget;  // none: half the available memory
  VolumeOpenOptions open;
  // The file the model was loaded from: its size gives the compression ratio, and it may record the
  // value range the model was trained with. Empty: the fp16 parameter bytes, no recorded range.
  std::string model_path;
};
// What happens while it runs: progress of a stage, "value range" (one scan of the volume) or "eval"
// (streamed slabs), its end, and notes for the user as they arise (also kept in FileEvaluation::notes).
struct FileEvalProgress {
  std::function<void(const std::string& stage, double fraction)> update;
  std::function<void(const std::string& stage)> finished;
  std::function<void(const std::string& text)> note;
};
struct FileEvaluation {
  FileEvalPlan plan;  // plan.method: how it was evaluated
  Device device = Device::Cpu;
  double psnr = 0, mse = 0;
  std::optional<double> ssim;                          // with_ssim and not Sampled
  std::optional<std::pair<double, double>> psnr_ci95;  // Sampled: the 95% interval
  double mse_stderr = 0;                               // Sampled
  double max_abs_error = 0;                            // normalised units (Sampled: among the samples)
  double max_abs_error_original = 0;                   // the same in original units
  int64_t samples = 0;                                 // voxels compared
  double decode_seconds = 0;
  ValueRange value_range;          // what the volume was normalised with
  std::string value_range_source;  // "volume", "model" or "scan" (file_evaluation_range)
  uint64_t model_bytes = 0, volume_bytes = 0;
  double compression_ratio = 0;    // volume_bytes / model_bytes
  std::vector<std::string> notes;  // e.g. a resolution other than the model's, streaming and why
  // Error-bound models (Model::residuals): the guaranteed max error in original units, and whether every
  // voxel compared (Sampled: every sample) is within it.
  std::optional<double> error_bound_original;
  bool bound_holds = true;
};
FileEvaluation evaluate_model_file(const Model& model, const std::string& volume_path, const FileEvalOptions& options,
                                   const FileEvalProgress& progress = {});

}  // namespace vnr
