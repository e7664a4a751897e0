#include "render_setup.h"
#include <cstring>
#include <fstream>
#include "vnr/core/error.h"
#include "vnr/core/fileio.h"
#include "vnr/core/json.h"

namespace vnr::cli {

bool is_model_path(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) fail("cannot open '{}'", path);
  char head[8] = {};
  f.read(head, 8);
  const std::streamsize got = f.gcount();
  if (got >= 8 && std::memcmp(head, "VNRMODEL", 8) == 0) return true;
  const std::string e = extension_of(path);
  if (e == ".vnr") return true;  // read_model reports what is wrong with it
  if (e == ".bson") return true;
  if (e == ".json") {
    // instantvnr's params.json is BSON (binary, starts with its int32 length); scenes and sidecars are text.
    for (std::streamsize i = 0; i < got; ++i) {
      unsigned char c = static_cast<unsigned char>(head[i]);
      if (c == ' ' || c == '\t' || c == '\n' || c == '\r') continue;
      return !(c == '{' || c == '/');
    }
  }
  return false;
}

RenderSource open_render_source(const std::string& input, const std::string& ground_truth, const VolumeArgs& va,
                                Precision precision) {
  RenderSource s;
  if (is_model_path(input)) {
    s.model = load_model(input);
    if (s.model->dims.count() == 0) fail("'{}' does not say which volume size it represents", input);
    s.dims = s.model->dims;
    s.model->net->set_inference_precision(precision);
    s.field = std::make_unique<NetworkField>(*s.model->net, s.dims);
    s.description = "model " + basename_of(input);
    if (!ground_truth.empty()) {
      s.volume = load_volume(describe_volume(ground_truth, va.raw()), va.load());
      if (!(s.volume->dims == s.dims))
        fail("the model represents {}x{}x{} voxels but '{}' has {}x{}x{}", s.dims.x, s.dims.y, s.dims.z, ground_truth,
             s.volume->dims.x, s.volume->dims.y, s.volume->dims.z);
    }
  } else {
    if (!ground_truth.empty()) fail("--volume is only for model inputs (the input '{}' is a volume)", input);
    s.volume = load_volume(describe_volume(input, va.raw()), va.load());
    s.dims = s.volume->dims;
    s.field = std::make_unique<GridField>(view_of(*s.volume));
    s.description = "volume " + basename_of(input);
    // An instantvnr scene given as the volume also brings its camera and transfer function.
    if (extension_of(input) == ".json" && parse_json_file(input).contains("dataSource")) s.scene = load_scene(input);
  }
  s.box = Vec3f{float(s.dims.x), float(s.dims.y), float(s.dims.z)};
  return s;
}

MacroCellMode default_macrocell_mode(const RenderSource& src) {
  if (src.model && src.model->macrocells) return MacroCellMode::Online;
  if (src.volume) return MacroCellMode::Grid;
  return MacroCellMode::Off;
}

MacroCells make_macrocells(const RenderSource& src, MacroCellMode mode, int cell_size, Device device) {
  switch (mode) {
    case MacroCellMode::Grid:
      if (!src.volume)
        fail("--macrocells grid needs the ground-truth volume: pass it with --volume (or use online/off)");
      if (device == Device::Cuda) return MacroCells(gpu_value_ranges_from_grid(view_of(*src.volume), cell_size), src.box);
      return MacroCells(value_ranges_from_grid(view_of(*src.volume), cell_size), src.box);
    case MacroCellMode::Online:
      if (!src.model || !src.model->macrocells)
        fail("--macrocells online needs a model trained by vnr (it records the value ranges of its training "
             "samples); use grid or off");
      return MacroCells(*src.model->macrocells, src.box);
    case MacroCellMode::Off:
    default:
      return MacroCells::single(src.dims, src.box);
  }
}

std::unique_ptr<FrameRenderer> make_setup_renderer(const RenderSetup& setup, const RenderSource& src,
                                                   const MacroCells& mc, const Camera& cam,
                                                   const RenderOptions& options) {
  return make_renderer(setup.device, *src.field, src.box, mc, setup.tf, cam, options, setup.mlp);
}

}  // namespace vnr::cli
