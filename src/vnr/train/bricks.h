#pragma once
// Brick-partitioned ("multi-brick") models: the volume split into a grid of bricks, one network per
// brick trained on its owned region plus a ghost layer, stored as a directory MODEL/ with
// manifest.json and one ordinary .vnr per brick (docs/MODEL_FORMAT.md, "Multi-brick models").
// Predictions of overlapping bricks are blended with core/brick_box.h's weights (1 inside the owned
// box, 0 at the ghost edge), so decodes and renderings show no seams.
//
// The single-process `vnr train --bricks` and the MPI layer both use: plan_bricks -> (assign_bricks)
// -> bricks_done (for --resume) -> train_brick for each missing brick -> write_manifest.
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>
#include "vnr/core/brick_box.h"
#include "vnr/json.h"
#include "vnr/cuda/cuda.h"
#include "vnr/train/model_io.h"
#include "vnr/train/session.h"
#include "vnr/volume/stream.h"

namespace vnr {

struct BrickSpec {
  int index = 0;     // x fastest over the brick grid
  Int3 coord;        // position in the brick grid
  Box3 owned;        // voxels this brick answers for; the owned boxes tile the volume
  Box3 trained;      // owned + ghost voxels on each side, clamped to the volume: what it learns from
  uint32_t seed = 0; // brick_seed(plan.seed, index)
  std::string file;  // "brick_00003.vnr", relative to the model directory
};

struct BrickPlan {
  Int3 dims;           // the whole volume
  Int3 grid{1, 1, 1};  // bricks per axis
  int ghost = 0;       // ghost voxels per side
  uint32_t seed = 1337;
  std::vector<BrickSpec> bricks;
};

// "BX,BY,BZ" or "auto" (grid {0,0,0}). auto: the fewest bricks of at most auto_brick_voxels voxels
// each, split along the longest axes first.
Int3 parse_brick_grid(const std::string& text);
constexpr uint64_t auto_brick_voxels = uint64_t(256) * 256 * 256;
// Splits dims into grid bricks (grid {0,0,0}: auto) as evenly as integers allow (the first
// dims % n bricks of an axis get one voxel more). Deterministic; every brick at least ghost + 1 voxels
// wide and at least 1 voxel (else an error saying how many bricks the axis allows).
BrickPlan plan_bricks(Int3 dims, Int3 grid, int ghost, uint32_t seed);
// The brick's boxes, seed and file as JSON (the manifest's entry; a brick file's training["brick"]).
Json brick_record(const BrickSpec& brick);
// Seed of brick `index` for the user's seed: a hash of both (never of the rank that trains it).
uint32_t brick_seed(uint32_t seed, int index);
// Bricks of each of n_ranks ranks, balanced by trained voxels (greedy largest-first onto the least
// loaded rank, ties by lower rank): result[rank] = brick indices, ascending. Deterministic.
std::vector<std::vector<int>> assign_bricks(const BrickPlan& plan, int n_ranks);
// Rank `rank` of n_ranks's share of the bricks for decoding: a run of consecutive indices (x fastest,
// so neighbours in x, then rows and layers), the runs balanced by owned voxels. A rank then needs
// only its bricks and their neighbours, where an even split of z-slices needs whole brick layers.
std::vector<int> contiguous_bricks(const BrickPlan& plan, int rank, int n_ranks);
// The voxels of an out_dims grid (a resampling of the model's, or the model's own) that brick `index`
// answers for: those whose centre lies in its owned box. The bricks' regions tile the grid exactly
// (integer arithmetic: no voxel on a face is lost or taken twice); a region may be empty.
Box3 brick_output_region(const BrickPlan& plan, int index, Int3 out_dims);
// Process `rank` of n_ranks's share of the model in directory `dir` for decoding or evaluating at dims:
// its bricks (contiguous_bricks), their non-empty output regions, and the model with those bricks and
// every brick within `reach` voxels of them loaded (the blend's and resampling's reach: 1; with the
// SSIM's windows: 7). A process without bricks (more than there are) loads brick 0 for the description.
struct BrickedModel;  // below
struct BrickShare {
  std::shared_ptr<BrickedModel> model;
  std::vector<Box3> regions;
  size_t loaded = 0;  // bricks loaded for the share (0 for a process without bricks)
};
BrickShare open_brick_share(const std::string& dir, Int3 dims, int reach, int rank, int n_ranks);

// What a brick's training does beyond the setup (setup.steps, seed, config, target_ratio apply per brick;
// setup.session.output is ignored: the brick's file is out_dir/spec.file).
struct BrickTrainOptions {
  int64_t steps = 1000;
  double seconds = 0;
  bool with_ssim = false;        // of the brick's own evaluation (on its trained region)
  MessageFn message;             // lines for people
  StepCallback on_step;          // progress of this brick's session
  std::atomic<bool>* stop = nullptr;  // set: the brick's session stops after its current step
};
struct BrickResult {
  int index = 0;
  int64_t steps = 0;
  double seconds = 0;
  float final_loss = 0;
  double psnr = 0;          // of the brick over its trained region
  uint64_t n_params = 0;
  uint64_t file_bytes = 0;
  bool interrupted = false; // stopped before its steps: its file is written but not complete (not "done")
};
// The global value range of the volume (descriptor, else one scan): every brick normalises with it.
ValueRange brick_value_range(const TrainingSetup& setup, const MessageFn& message = {});
// Trains brick `index` of `plan` from its trained region only (read with pread, normalised with
// `range`), seeded by its BrickSpec::seed, and writes out_dir/spec.file atomically with the brick's
// record ("brick": index, owned, trained, seed, complete) in its training summary. setup.target_ratio
// applies to the whole model: the brick is sized for its owned voxels at that ratio.
BrickResult train_brick(const TrainingSetup& setup, const BrickPlan& plan, int index, const std::string& out_dir,
                        const ValueRange& range, const BrickTrainOptions& options = {});

// Creates out_dir for plan. Without resume an existing non-empty directory is an error (no data is
// replaced); with resume an existing manifest must describe the same plan (dims, grid, ghost, seed).
void prepare_brick_dir(const std::string& out_dir, const BrickPlan& plan, bool resume);
// The training summaries recorded in the brick files of the bricks marked done.
std::vector<BrickResult> brick_results_on_disk(const std::string& out_dir, const BrickPlan& plan,
                                               const std::vector<bool>& done);

// The manifest's "training" summary (write_manifest) of the bricks done, from their results on disk:
// bricks done of all, complete, steps per brick (null when negative: --seconds limited each brick),
// the bricks' summed steps and seconds, batch, seed and target_ratio.
Json bricks_training_summary(const TrainingSetup& setup, const BrickPlan& plan, const std::vector<BrickResult>& done,
                             int64_t steps_per_brick);

// The single-process run of `vnr train --bricks`: prepare the directory, write the manifest, train every
// brick not done (in index order, or those in `only`), rewrite the manifest with every finished brick.
struct BricksRunOptions {
  bool resume = false;
  BrickTrainOptions brick;
  std::function<void(const BrickSpec& brick, int k, int n)> on_brick_start;  // k of n bricks to train
  std::function<void(const BrickResult& result)> on_brick_done;
};
struct BricksRunResult {
  BrickPlan plan;
  ValueRange range;
  int already_done = 0;              // bricks found complete on disk (--resume)
  std::vector<BrickResult> trained;  // this run's bricks
  bool interrupted = false;          // a stop was requested: the remaining bricks are missing
  int done = 0;                      // bricks complete on disk after this run
  bool complete = false;             // every brick is done
  double seconds = 0;
};
BricksRunResult train_bricks(const TrainingSetup& setup, Int3 grid, int ghost, const std::string& out_dir,
                             const BricksRunOptions& options);

// Which bricks of plan are already trained in out_dir: the file loads (CRC checked), covers the brick's
// trained box with the brick's seed and is complete. A damaged or foreign file counts as missing.
std::vector<bool> bricks_done(const std::string& out_dir, const BrickPlan& plan, const std::string& config_text);
// Writes out_dir/manifest.json atomically: format, dims, dtype, value range, grid, ghost, seed, config, and
// per brick its boxes, seed, file and (from results, when given) its training summary.
void write_manifest(const std::string& out_dir, const BrickPlan& plan, DType dtype, const ValueRange& range,
                    const Json& config, const std::vector<BrickResult>& results, const Json& training = {});
// The plan a manifest describes (checked: boxes tile the volume, files named).
BrickPlan read_manifest_plan(const Json& manifest, const std::string& where);
bool is_bricked_model_dir(const std::string& path);  // a directory holding manifest.json
// Bytes of a model on disk: the file, or a multi-brick directory's manifest and brick files.
uint64_t model_file_bytes(const std::string& path);

// A multi-brick model in memory: its plan and the bricks' models (a brick not loaded is empty).
struct BrickedModel {
  std::string dir;
  BrickPlan plan;
  BrickLayout layout;  // the plan's boxes, for blending
  Json manifest;
  DType source_dtype = DType::Float32;
  double lo = 0, hi = 1;
  std::vector<std::optional<Model>> bricks;
  uint64_t param_bytes() const;  // fp16 parameters of the loaded bricks
  uint64_t file_bytes() const;   // manifest + brick files on disk
};
// Opens MODEL/ (only the bricks in `only` when given: a rank's bricks and their neighbours). A missing or
// damaged brick file is one error naming the brick and suggesting --resume.
std::shared_ptr<BrickedModel> load_bricked_model(const std::string& dir, const std::vector<int>* only = nullptr);
// The Model load_model(dir) returns: dims, dtype, range, training summary and merged macro-cells of the
// whole volume, bricks = m, net = a network of the bricks' config (for its description and precision).
Model model_of_bricks(std::shared_ptr<BrickedModel> m);
BrickLayout layout_of(const BrickPlan& plan);
// Bricks whose trained box meets `region` (voxels of the model's grid): what must be loaded to answer it.
std::vector<int> bricks_touching(const BrickPlan& plan, const Box3& region);

// Brick b's network at n points of its own normalised coordinates (xyz interleaved) -> out: what the
// blends below call; empty: the brick's Network on the CPU. BrickGpuNetworks::infer runs them on the GPU.
using BrickInfer = std::function<void(int b, const float* xyz, int64_t n, float* out)>;
// Blended values (normalised) at n points given in normalised coordinates of the whole volume (xyz
// interleaved): each point's bricks (those whose trained box contains it) weighted by brick_blend_weight.
void bricked_points(const BrickedModel& m, const float* xyz, int64_t n, float* out, const BrickInfer& infer = {});
// Voxel centres of `region` of an out_dims grid (x fastest within the region) -> out: the values of
// bricked_points at those centres. decode_bricked_region(m, dims, {{0,0,z0},{dims.x,dims.y,z1}}) is a z-slab.
void decode_bricked_region(const BrickedModel& m, Int3 out_dims, const Box3& region, float* out,
                           const BrickInfer& infer = {});

// The bricks' networks on the GPU for the blends above: each copied on first use, the least recently
// used released when more would not fit a quarter of the GPU's free memory (at least one stays).
class BrickGpuNetworks {
public:
  explicit BrickGpuNetworks(const BrickedModel& m, cuda::MlpPath mlp = cuda::MlpPath::Auto);
  ~BrickGpuNetworks();
  void infer(int b, const float* xyz, int64_t n, float* out);
  BrickInfer fn() {
    return [this](int b, const float* xyz, int64_t n, float* out) { infer(b, xyz, n, out); };
  }
  size_t capacity() const { return capacity_; }  // networks held at once

private:
  const BrickedModel& m_;
  cuda::MlpPath mlp_;
  std::vector<std::unique_ptr<cuda::GpuNetwork>> nets_;
  std::vector<uint64_t> last_use_;
  uint64_t clock_ = 0;
  size_t capacity_ = 1, live_ = 0;
};

// The model's value ranges for rendering: the bricks' online macro-cells merged into one grid over the
// whole volume (a brick's cells mapped conservatively into the global cells they overlap), or none.
std::optional<ValueRangeGrid> merged_macrocells(const BrickedModel& m);

}  // namespace vnr
