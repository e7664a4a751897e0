#pragma once
// Multi-brick models in the public API (docs/MODEL_FORMAT.md, "Multi-brick models").
// Brick-partitioned ("multi-brick") models: the volume split into a grid of bricks, one network per
// brick trained on its owned region plus a ghost layer, stored as a directory MODEL/ with
// manifest.json and one ordinary .vnr per brick (docs/MODEL_FORMAT.md, "Multi-brick models").
// Predictions of overlapping bricks are blended with core/brick_box.h's weights (1 inside the owned
// box, 0 at the ghost edge), so decodes and renderings show no seams.
//
// The single-process `vnr train --bricks` and the MPI layer both use: plan_bricks -> (assign_bricks)
// -> bricks_done (for --resume) -> train_brick for each missing brick -> write_manifest.
//
// load_model(path) opens a model directory like a .vnr file: the Model it returns carries the bricks
// (Model::bricks), and ModelQuery, evaluate_model(_file), Renderer and `vnr info` answer for the whole
// volume, blending the bricks. Below: planning, per-brick training, the manifest, and what a distributed
// front end (the MPI layer) adds: ranks' shares, their evaluation, sort-last rendering.
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>
#include "vnr/image.h"
#include "vnr/json.h"
#include "vnr/math.h"
#include "vnr/model.h"
#include "vnr/opaque.h"
#include "vnr/renderer.h"
#include "vnr/trainer.h"
#include "vnr/training_options.h"

namespace vnr {

struct BrickLayout;  // core/brick_box.h: the plan's boxes as blending reads them

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

// A multi-brick model in memory: its plan and the bricks' models (a brick not loaded is empty).
struct BrickedModel {
  BrickedModel();
  ~BrickedModel();
  std::string dir;
  BrickPlan plan;
  Opaque<BrickLayout> layout;  // the plan's boxes, for blending (core/brick_box.h)
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
// Every loaded brick's CPU inference arithmetic, as set_inference_precision(Model&) sets a model's.
void set_inference_precision(BrickedModel& m, Precision precision);
// The Model load_model(dir) returns: dims, dtype, range, training summary and merged macro-cells of the
// whole volume, bricks = m, net = a network of the bricks' config (for its description and precision).
Model model_of_bricks(std::shared_ptr<BrickedModel> m);

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
struct BrickShare {
  std::shared_ptr<BrickedModel> model;
  std::vector<Box3> regions;
  size_t loaded = 0;  // bricks loaded for the share (0 for a process without bricks)
};
BrickShare open_brick_share(const std::string& dir, Int3 dims, int reach, int rank, int n_ranks);

// Bricks whose trained box meets `region` (voxels of the model's grid): what must be loaded to answer it.
std::vector<int> bricks_touching(const BrickPlan& plan, const Box3& region);

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

// A share of a multi-brick model's evaluation against a volume file (desc, at the model's grid; read at
// random offsets, so uncompressed) normalised with range: evaluate_region over each of regions, added up
// (an MPI rank's share: BrickShare::regions).
EvalSums evaluate_regions(const Model& model, const VolumeDesc& desc, ValueRange range, NonFinitePolicy policy,
                          const std::vector<Box3>& regions, bool with_ssim);

// The bricked part of a model opened by load_model (null for a single-network model).
inline const BrickedModel* bricked(const Model& m) { return m.bricks.get(); }

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

// Distributed decode and evaluation: a rank opens its share (open_brick_share: contiguous_bricks(plan,
// rank, n) and their neighbours loaded), decodes brick_output_region of each (decode_bricked_region), and
// evaluate_regions(model, volume, ..., share.regions) gives its share of the evaluation (errors, and with
// SSIM the windows starting in it); the ranks' EvalSums add up to the single-process evaluation. The rank
// needs its bricks and those within 7 voxels loaded.

// Sort-last rendering (ray marching without shadows): brick `index`'s part of every ray of the renderer's
// current settings (frame 0), as premultiplied RGBA without background, and per pixel the ray
// parameter t of the brick's first sample (+inf where it has none). Samples lie on the same t grid as
// the whole-volume frame (the march and its macro-cells are the whole model's; a sample belongs to the
// brick owning its position), so composite_brick_segments of every brick's segment gives the
// single-process frame up to float rounding. Needs the bricks within ghost + 1 voxels of the brick
// loaded (gradients and the blend reach into them): bricks_touching(plan, owned box grown by ghost + 1).
// The march must see the same macro-cells on every rank: the merged online ranges need every brick
// loaded (model_of_bricks gives none when some are missing), so a rank holding only some bricks sets
// MacroCellMode::Off (or Grid from the volume) on its Renderer, as the reference frame must.
struct BrickSegment {
  int index = 0;
  Image rgba;                 // premultiplied, no background
  std::vector<float> t_first; // width * height
};
BrickSegment render_brick_segment(Renderer& renderer, int index);
// Front-to-back "over" of the segments per pixel, ordered by t_first, then the background.
Image composite_brick_segments(const std::vector<const BrickSegment*>& segments, Vec3f background);

}  // namespace vnr
