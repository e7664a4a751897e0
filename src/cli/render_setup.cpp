#include "render_setup.h"
#include <cmath>
#include <cstdio>
#include "vnr/error.h"

namespace vnr::cli {

namespace {

Vec3f parse_vec3(const std::string& s, const char* what) {
  float v[3];
  char tail;
  if (std::sscanf(s.c_str(), "%f,%f,%f%c", &v[0], &v[1], &v[2], &tail) != 3 || !std::isfinite(v[0]) ||
      !std::isfinite(v[1]) || !std::isfinite(v[2]))
    fail("{} expects X,Y,Z (three numbers), got '{}'", what, s);
  return Vec3f{v[0], v[1], v[2]};
}

// --eye/--center (with --up, --fovy), else --orbit AZIMUTH[,ELEVATION], else the scene's camera or the
// default orbit (camera_for).
Camera parse_camera(const RenderArgs& a, const Scene& scene, Vec3f box, float* orbit_elevation) {
  if (a.eye.empty() != a.center.empty()) fail("--eye and --center go together");
  CameraRequest r;
  if (!a.eye.empty()) r.eye = parse_vec3(a.eye, "--eye");
  if (!a.center.empty()) r.center = parse_vec3(a.center, "--center");
  r.up = parse_vec3(a.up, "--up");
  r.fovy = a.fovy;
  if (!a.orbit.empty()) {
    float az = 0, el = 0;
    char tail;
    const int got = std::sscanf(a.orbit.c_str(), "%f,%f%c", &az, &el, &tail);
    if (got < 1 || got > 2) fail("--orbit expects AZIMUTH[,ELEVATION] in degrees, got '{}'", a.orbit);
    r.orbit = std::make_pair(az, el);
  }
  const Camera cam = camera_for(r, box, scene.camera);
  if (!r.eye && (r.orbit || !scene.camera)) *orbit_elevation = r.orbit ? r.orbit->second : 0;
  return cam;
}

}  // namespace

CliRender open_cli_render(const std::string& input, const RenderArgs& a, const VolumeArgs& va, int frames) {
  CliRender c;
  c.input = std::make_unique<RenderInput>(open_render_input(input, a.volume, va.open(), parse_precision(a.precision)));
  RenderOptions o;
  o.mode = parse_render_mode(a.mode);
  parse_size(a.size, &o.width, &o.height);
  o.step = a.step;
  o.step_max = a.step_max;
  o.seed = a.seed;
  o.samples_per_iteration = a.k > 0 ? a.k : kDefaultSamplesPerIteration;
  o.shade = a.shade;
  o.ray_packets = a.ray_packets == "on";
  o.density_scale = a.density;
  const Scene scene = a.scene.empty() ? c.input->scene : load_scene(a.scene);
  std::optional<TransferFunction> tf;
  if (!a.tf.empty()) tf = load_transfer_function(a.tf);
  const Model* model = c.input->model ? &*c.input->model : nullptr;
  const Volume* volume = c.input->volume ? &*c.input->volume : nullptr;
  const Int3 dims = model ? model->dims : volume->dims;
  const Vec3f box{float(dims.x), float(dims.y), float(dims.z)};  // Renderer::box() of this input
  const Camera camera = parse_camera(a, scene, box, &c.orbit_elevation);
  o.light = scene.light.value_or(DirectionalLight{});
  o.background = scene.background.value_or(Vec3f{0, 0, 0});
  if (!a.light.empty()) o.light.direction = parse_vec3(a.light, "--light");
  if (!a.background.empty()) o.background = parse_vec3(a.background, "--background");
  const MacroCellMode mc_mode =
      a.macrocells.empty() ? default_macrocell_mode(model, volume) : parse_macrocell_mode(a.macrocells);
  std::string note;
  const Device device = choose_render_device(a.device, model, &note);
  if (!note.empty()) std::fprintf(stderr, "note: %s\n", note.c_str());
  const cuda::MlpPath mlp = cuda::parse_mlp_path(a.mlp);
  if (a.macrocell_size < 1) fail("--macrocell-size must be at least 1, got {}", a.macrocell_size);

  c.renderer = std::make_unique<Renderer>(*c.input, device);
  Renderer& r = *c.renderer;
  r.set_scene(scene);  // camera and transfer function; the options below override them
  if (tf) r.set_transfer_function(*tf);
  r.set_camera(camera);
  r.set_options(o);
  Int3 cache_dims{0, 0, 0};
  if (!a.cache_dims.empty()) {
    cache_dims = parse_dims(a.cache_dims, "--cache-dims");
    if (!model) fail("--cache-dims is for models (a volume is drawn directly)");
  }
  r.choose_strategy(a.strategy, parse_cache_budget(a.cache_budget), cache_dims, frames);
  if (cache_dims.count() > 0 && !r.cache()) fail("--cache-dims needs the brick cache (--strategy cache or auto on the CPU)");
  if (model && model->residuals)
    std::fprintf(stderr, "note: %s\n",
                 r.cache() ? "the model's residuals apply where the cache reads full-resolution bricks (voxels no "
                             "larger than a pixel); coarser bricks and direct queries show the network alone"
                           : "the image shows the network alone; the model's residuals apply with --strategy cache "
                             "and to `vnr decode`");
  r.set_macrocells(mc_mode, a.macrocell_size);
  r.set_mlp_path(mlp);
  return c;
}

}  // namespace vnr::cli
