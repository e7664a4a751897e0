#pragma once
// What `vnr render` and `vnr bench render` share: opening a model or a volume as a field, choosing the
// macro-cells, and the scene defaults.
#include <memory>
#include <optional>
#include <string>
#include "cli.h"
#include "vnr/fields/fields.h"
#include "vnr/render/macrocell.h"
#include "vnr/render/renderer.h"
#include "vnr/render/scene.h"
#include "vnr/render_cuda/gpu_renderer.h"
#include "vnr/train/model_io.h"

namespace vnr::cli {

struct RenderSource {
  std::optional<Model> model;    // when the input is a model
  std::optional<Volume> volume;  // the input volume, or the ground truth given with --volume
  std::unique_ptr<RenderableField> field;  // rendered: the model if there is one, else the volume
  Int3 dims;
  Vec3f box;                     // world size: dims (voxel units)
  Scene scene;                   // from an instantvnr scene given as the input
  std::string description;       // for messages and reports
};

// True when `path` holds a model (.vnr by its magic, or instantvnr BSON); false for anything that
// describes a volume (sidecars, scenes, NRRD, raw).
bool is_model_path(const std::string& path);

// input: model or volume; ground_truth: optional volume (for --macrocells grid with a model, and for
// comparisons).
// A model's network infers with `precision` (the in-shader evaluator and the batched queries alike).
RenderSource open_render_source(const std::string& input, const std::string& ground_truth, const VolumeArgs& va,
                                Precision precision);

// Macro-cells of a mode for a source: grid needs a volume, online needs a model trained by vnr (its
// recorded value ranges), off is one cell. `cell_size` applies to grid, whose ranges are computed on the
// device that renders.
MacroCells make_macrocells(const RenderSource& src, MacroCellMode mode, int cell_size, Device device = Device::Cpu);
// The default mode: online for a model that carries ranges, grid when a volume is at hand, else off.
MacroCellMode default_macrocell_mode(const RenderSource& src);

// Options, transfer function and camera from the command line, the scene and the defaults.
struct RenderSetup {
  RenderOptions options;
  TransferFunction tf;
  Camera camera;
  MacroCellMode macrocell_mode = MacroCellMode::Off;
  Device device = Device::Cpu;  // --device resolved: auto renders on a visible GPU the model can run on
  cuda::MlpPath mlp = cuda::MlpPath::Auto;
  float orbit_elevation = 0;  // degrees, from --orbit
};
RenderSetup make_render_setup(const RenderArgs& a, const RenderSource& src);
// The renderer for a setup (CPU or GPU) over the source's field.
std::unique_ptr<FrameRenderer> make_setup_renderer(const RenderSetup& setup, const RenderSource& src,
                                                   const MacroCells& mc, const Camera& cam,
                                                   const RenderOptions& options);

}  // namespace vnr::cli
