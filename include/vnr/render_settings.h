#pragma once
// One rendering request, as `vnr render`, `vnr bench render`, `vnr mpi render` and Python's vnr.render
// state it: the defaults in one place, read from and written to JSON (unknown keys refused with the
// allowed list). setup_renderer (vnr/renderer.h) turns it into a Renderer.
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include "vnr/json.h"
#include "vnr/math.h"

namespace vnr {

struct RenderSettings {
  // The picture.
  std::string mode = "raymarch";  // raymarch | shadow | pathtrace
  std::string strategy = "auto";  // auto | cache | streaming | inshader (Renderer::choose_strategy)
  int width = 768, height = 768;
  float step = 1;                 // s1 in voxels
  float step_max = 0;             // s2 in voxels; 0 = 16 x step
  float density = 1;              // path tracing: extinction per voxel = opacity x density
  bool shade = false;             // gradient shading for ray marching
  uint32_t seed = 0;              // jitter and path-tracing random numbers
  int samples_per_iteration = 0;  // streaming K; 0 = the default (kDefaultSamplesPerIteration)
  bool ray_packets = true;        // in-shader grid ray marching in SIMD packets (false: per ray; same image)
  std::optional<Vec3f> light;       // direction toward the light; else the scene's, else the default
  std::optional<Vec3f> background;  // RGB; else the scene's, else black
  std::string tf;                 // a preset, transfer-function JSON text or a file; "" = the scene's, else "ramp"
  std::string scene;              // a scene file (instantvnr or vnr JSON); "" = the input's own
  std::string macrocells;         // grid | online | off; "" = default_macrocell_mode
  int macrocell_size = 16;        // voxels per cell of grid macro-cells

  // The camera: eye and center (with up and fovy), else an orbit (azimuth, elevation in degrees), else
  // the scene's camera, else the orbit (0, 0).
  std::optional<Vec3f> eye, center;
  Vec3f up{0, 1, 0};
  float fovy = 30;
  std::optional<std::pair<float, float>> orbit;

  // Where it runs.
  std::string device = "auto";     // auto | cpu | cuda
  std::string mlp = "auto";        // cuda streaming inference: auto | fused | cublas
  std::string precision = "auto";  // a model's inference precision when it is opened: auto | fp32 | bf16
  uint64_t cache_budget = 0;       // bytes of the brick cache's pool; 0 = default_cache_budget()
  Int3 cache_dims{0, 0, 0};        // the voxels the cache decodes a model at; 0 = the model's dims

  // How many frames are accumulated: spp, or with spp 0 until the image's noise is at most `noise`
  // (after at least 4 frames), at most max_spp.
  int spp = 0;
  double noise = 1.0 / 255;
  int max_spp = 256;

  // Fails with one line naming the setting unless every value is one vnr renders. `name` turns a key
  // into the front end's name for it (the CLI's "--max-spp"); none: the key itself (JSON, Python).
  void validate(const std::function<std::string(const std::string&)>& name = {}) const;
  // Every key optional (the defaults above); sizes as [w, h], vectors as [x, y, z], orbit as
  // [azimuth, elevation], cache_budget as bytes or text ("512MiB", "auto"). Validates.
  static RenderSettings from_json(const Json& j);
  Json to_json() const;
};

}  // namespace vnr
