// RenderSettings (vnr/render_settings.h): validation and JSON; setup_renderer (vnr/renderer.h), the one
// place a rendering request becomes a Renderer for every front end.
#include "vnr/render_settings.h"
#include <cmath>
#include <set>
#include "vnr/error.h"
#include "vnr/fields/brick_cache.h"
#include "vnr/nn/json_get.h"
#include "vnr/renderer.h"

namespace vnr {

namespace {

constexpr int kMaxImageSide = 32768;
const char* const kWhere = "render settings";

bool finite3(const Vec3f& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

Json vec_json(const Vec3f& v) { return Json::array({v.x, v.y, v.z}); }

Vec3f vec_of(const Json& j, const char* key) {
  if (!j.is_array() || j.size() != 3 || !j[0].is_number() || !j[1].is_number() || !j[2].is_number())
    fail("{}: '{}' must be [x, y, z] (three numbers), got {}", kWhere, key, j.dump());
  return Vec3f{j[0].get<float>(), j[1].get<float>(), j[2].get<float>()};
}

std::optional<Vec3f> optional_vec(const Json& j, const char* key) {
  auto it = j.find(key);
  if (it == j.end() || it->is_null()) return std::nullopt;
  return vec_of(*it, key);
}

// The keys read with json_get and written as they are: f(key, field) for each, the one list of them.
template <class Settings, class F>
void for_each_plain_key(Settings& s, F&& f) {
  f("mode", s.mode), f("strategy", s.strategy), f("step", s.step), f("step_max", s.step_max);
  f("density", s.density), f("shade", s.shade), f("seed", s.seed);
  f("samples_per_iteration", s.samples_per_iteration), f("ray_packets", s.ray_packets), f("tf", s.tf);
  f("scene", s.scene), f("macrocells", s.macrocells), f("macrocell_size", s.macrocell_size), f("fovy", s.fovy);
  f("device", s.device), f("mlp", s.mlp), f("precision", s.precision), f("spp", s.spp), f("noise", s.noise);
  f("max_spp", s.max_spp);
}

const std::set<std::string>& known_keys() {
  static const std::set<std::string> keys = [] {
    std::set<std::string> k = {"size",  "light", "background", "eye",          "center",
                               "up",    "orbit", "cache_budget", "cache_dims"};  // read below, by hand
    RenderSettings s;
    for_each_plain_key(s, [&k](const char* key, const auto&) { k.insert(key); });
    return k;
  }();
  return keys;
}

void check_one_of(const std::string& value, std::initializer_list<const char*> allowed, const char* key) {
  std::string list;
  for (const char* a : allowed) {
    if (value == a) return;
    list += (list.empty() ? "" : ", ") + std::string(a);
  }
  fail("unknown {} '{}' (allowed: {})", key, value, list);
}

}  // namespace

bool names_a_tf_file(const std::string& tf) {
  const size_t first = tf.find_first_not_of(" \t\r\n");
  return !tf.empty() && !is_tf_preset(tf) && (first == std::string::npos || tf[first] != '{');
}

TransferFunction transfer_function_of(const std::string& tf) {
  if (tf.empty()) return tf_preset("ramp");
  if (is_tf_preset(tf)) return tf_preset(tf);
  if (!names_a_tf_file(tf)) {
    Json j;
    try {
      j = Json::parse(tf);
    } catch (const std::exception& e) {
      fail("the transfer function is not valid JSON: {}", e.what());
    }
    return tf_from_json(j, "tf");
  }
  return load_transfer_function(tf);
}

void RenderSettings::validate(const std::function<std::string(const std::string&)>& name) const {
  auto n = [&name](const char* key) { return name ? name(key) : std::string(key); };
  parse_render_mode(mode);
  check_one_of(strategy, {"auto", "cache", "streaming", "inshader"}, "render strategy");
  if (width < 1 || height < 1 || width > kMaxImageSide || height > kMaxImageSide)
    fail("{}: the image must be positive and at most {} a side, got {}x{}", n("size"), kMaxImageSide, width, height);
  if (!(std::isfinite(step) && step > 0)) fail("{} must be a positive number of voxels, got {}", n("step"), step);
  if (!(std::isfinite(step_max) && step_max >= 0))
    fail("{} must be at least 0 (0: 16 x step), got {}", n("step_max"), step_max);
  if (!(std::isfinite(density) && density > 0)) fail("{} must be positive, got {}", n("density"), density);
  if (samples_per_iteration < 0)
    fail("{} must be at least 0 (0: the default), got {}", n("samples_per_iteration"), samples_per_iteration);
  for (const auto& [v, key] : {std::pair{light, "light"}, std::pair{background, "background"}, std::pair{eye, "eye"},
                               std::pair{center, "center"}, std::pair{std::optional<Vec3f>(up), "up"}})
    if (v && !finite3(*v)) fail("{} must be finite", n(key));
  if (!macrocells.empty()) parse_macrocell_mode(macrocells);
  if (macrocell_size < 1) fail("{} must be at least 1, got {}", n("macrocell_size"), macrocell_size);
  if (eye.has_value() != center.has_value()) fail("{} and {} go together", n("eye"), n("center"));
  if (!(fovy > 0 && fovy < 180)) fail("{} must be in (0, 180) degrees, got {}", n("fovy"), fovy);
  if (orbit && !(std::isfinite(orbit->first) && std::isfinite(orbit->second)))
    fail("{} must be finite (azimuth, elevation), got ({}, {})", n("orbit"), orbit->first, orbit->second);
  check_one_of(device, {"auto", "cpu", "cuda"}, "device");
  cuda::parse_mlp_path(mlp);
  parse_precision(precision);
  if (!(cache_dims == Int3{0, 0, 0}) && (cache_dims.x < 1 || cache_dims.y < 1 || cache_dims.z < 1))
    fail("{} must be positive (x, y, z), or all 0 for the model's dims, got ({}, {}, {})", n("cache_dims"),
         cache_dims.x, cache_dims.y, cache_dims.z);
  if (spp < 0) fail("{} must be at least 1, or 0 (auto: until converged), got {}", n("spp"), spp);
  if (!(noise >= 0)) fail("{} must be at least 0, got {}", n("noise"), noise);
  if (max_spp < Convergence{}.min_frames)
    fail("{} must be at least {}, got {}", n("max_spp"), Convergence{}.min_frames, max_spp);
}

RenderSettings RenderSettings::from_json(const Json& j) {
  json_check_keys(j, known_keys(), kWhere);
  RenderSettings s;
  for_each_plain_key(s, [&j](const char* key, auto& field) { field = json_get(j, key, field, kWhere); });
  if (auto it = j.find("size"); it != j.end()) {
    if (!it->is_array() || it->size() != 2 || !(*it)[0].is_number_integer() || !(*it)[1].is_number_integer())
      fail("{}: 'size' must be [width, height] (integers), got {}", kWhere, it->dump());
    s.width = (*it)[0].get<int>();
    s.height = (*it)[1].get<int>();
  }
  s.light = optional_vec(j, "light");
  s.background = optional_vec(j, "background");
  s.eye = optional_vec(j, "eye");
  s.center = optional_vec(j, "center");
  if (auto up = optional_vec(j, "up")) s.up = *up;
  if (auto it = j.find("orbit"); it != j.end() && !it->is_null()) {
    if (!it->is_array() || it->empty() || it->size() > 2 || !(*it)[0].is_number() ||
        (it->size() == 2 && !(*it)[1].is_number()))
      fail("{}: 'orbit' must be [azimuth, elevation] in degrees, got {}", kWhere, it->dump());
    s.orbit = std::make_pair((*it)[0].get<float>(), it->size() == 2 ? (*it)[1].get<float>() : 0.0f);
  }
  if (auto it = j.find("cache_budget"); it != j.end()) {
    if (it->is_string()) s.cache_budget = parse_cache_budget(it->get<std::string>());
    else if (it->is_number_unsigned()) s.cache_budget = it->get<uint64_t>();
    else fail("{}: 'cache_budget' must be bytes or text such as \"512MiB\" or \"auto\", got {}", kWhere, it->dump());
  }
  if (auto it = j.find("cache_dims"); it != j.end() && !it->is_null()) {
    if (!it->is_array() || it->size() != 3 || !(*it)[0].is_number_integer() || !(*it)[1].is_number_integer() ||
        !(*it)[2].is_number_integer())
      fail("{}: 'cache_dims' must be [x, y, z] (integers), got {}", kWhere, it->dump());
    s.cache_dims = Int3{(*it)[0].get<int64_t>(), (*it)[1].get<int64_t>(), (*it)[2].get<int64_t>()};
  }
  s.validate();
  return s;
}

Json RenderSettings::to_json() const {
  Json j = {{"size", {width, height}},
            {"up", vec_json(up)},
            {"cache_budget", cache_budget},
            {"cache_dims", {cache_dims.x, cache_dims.y, cache_dims.z}}};
  for_each_plain_key(*this, [&j](const char* key, const auto& field) { j[key] = field; });
  if (light) j["light"] = vec_json(*light);
  if (background) j["background"] = vec_json(*background);
  if (eye) j["eye"] = vec_json(*eye);
  if (center) j["center"] = vec_json(*center);
  if (orbit) j["orbit"] = {orbit->first, orbit->second};
  return j;
}

RenderSetup setup_renderer(const Model* model, const Volume* volume, const Scene& input_scene, const RenderSettings& s) {
  s.validate();
  if (!model && !volume) fail("nothing to render: neither a model nor a volume");
  if (!model && s.cache_dims.count() > 0) fail("cache_dims is for models (a volume is drawn directly)");
  RenderSetup out;
  RenderOptions o;
  o.mode = parse_render_mode(s.mode);
  o.width = s.width;
  o.height = s.height;
  o.step = s.step;
  o.step_max = s.step_max;
  o.seed = s.seed;
  o.samples_per_iteration = s.samples_per_iteration > 0 ? s.samples_per_iteration : kDefaultSamplesPerIteration;
  o.shade = s.shade;
  o.ray_packets = s.ray_packets;
  o.density_scale = s.density;
  const Scene scene = s.scene.empty() ? input_scene : load_scene(s.scene);
  o.light = scene.light.value_or(DirectionalLight{});
  o.background = scene.background.value_or(Vec3f{0, 0, 0});
  if (s.light) o.light.direction = *s.light;
  if (s.background) o.background = *s.background;
  std::optional<TransferFunction> tf;
  if (!s.tf.empty()) tf = transfer_function_of(s.tf);
  const MacroCellMode mc_mode = s.macrocells.empty() ? default_macrocell_mode(model, volume) : parse_macrocell_mode(s.macrocells);
  std::string note;
  const Device device = choose_render_device(s.device, model, &note);
  if (!note.empty()) out.notes.push_back(note);

  out.renderer = model ? std::make_unique<Renderer>(*model, device, volume) : std::make_unique<Renderer>(*volume, device);
  Renderer& r = *out.renderer;
  r.set_scene(scene);  // camera and transfer function; the settings below override them
  if (tf) r.set_transfer_function(*tf);
  CameraRequest request;
  request.eye = s.eye;
  request.center = s.center;
  request.up = s.up;
  request.fovy = s.fovy;
  request.orbit = s.orbit;
  r.set_camera(camera_for(request, r.box(), scene.camera));
  if (!request.eye && (request.orbit || !scene.camera)) out.orbit_elevation = request.orbit ? request.orbit->second : 0;
  r.set_options(o);
  r.choose_strategy(s.strategy, s.cache_budget, s.cache_dims, s.spp);
  if (s.cache_dims.count() > 0 && !r.cache())
    fail("cache_dims needs the brick cache (strategy cache, or auto on the CPU)");
  if (model && model->residuals)
    out.notes.push_back(r.cache() ? "the model's residuals apply where the cache reads full-resolution bricks (voxels "
                                    "no larger than a pixel); coarser bricks and direct queries show the network alone"
                                  : "the image shows the network alone; the model's residuals apply with the brick "
                                    "cache (strategy cache) and to a decode");
  r.set_macrocells(mc_mode, s.macrocell_size);
  r.set_mlp_path(cuda::parse_mlp_path(s.mlp));
  return out;
}

}  // namespace vnr
