// vnr.render: one image of a model or a volume with vnr::Renderer, set up as `vnr render` sets it up
// (src/cli/render_setup.cpp) for the same camera, transfer function and options.
#include "bindings.h"
#include "vnr/error.h"
#include "vnr/json.h"

namespace vnr::py {

namespace {

using Vec3 = std::array<float, 3>;
Vec3f vec(const Vec3& v) { return Vec3f{v[0], v[1], v[2]}; }

struct RenderArgs {
  std::optional<Vec3> eye, center;
  Vec3 up{0, 1, 0};
  float fovy = 30;
  std::optional<std::pair<float, float>> orbit;  // azimuth, elevation in degrees
  std::string tf, mode, strategy, device;
  std::optional<std::string> macrocells;
  std::pair<int, int> size{512, 512};
  int spp = 1;  // 0: until converged (noise, max_spp)
  double noise = 1.0 / 255;
  int max_spp = 256;
  float step = 1;
  uint32_t seed = 0;
  bool shade = false;
  std::optional<Vec3> background, light;
  std::string cache_budget;                            // "" or "auto": default_cache_budget()
  std::optional<std::tuple<int64_t, int64_t, int64_t>> cache_dims;  // (x, y, z); none: the model's dims
};

// A preset name, the JSON text of a transfer function (instantvnr's or vnr's, as --tf files hold)
// or the path of such a file.
TransferFunction transfer_function_of(const std::string& tf) {
  if (tf.empty()) return tf_preset("ramp");
  if (is_tf_preset(tf)) return tf_preset(tf);
  const size_t first = tf.find_first_not_of(" \t\r\n");
  if (first != std::string::npos && tf[first] == '{') {
    Json j;
    try {
      j = Json::parse(tf);
    } catch (const std::exception& e) {
      fail("the transfer function is not valid JSON: {}", e.what());
    }
    return tf_from_json(j, "tf");
  }
  require_file(tf, "transfer function");
  return load_transfer_function(tf);
}

Camera camera_of(const RenderArgs& a, Vec3f box) {
  CameraRequest r;
  if (a.eye) r.eye = vec(*a.eye);
  if (a.center) r.center = vec(*a.center);
  r.up = vec(a.up);
  r.fovy = a.fovy;
  r.orbit = a.orbit;
  return camera_for(r, box);
}

// `model_mutex` (the model's holder's, or null) is locked only once the GIL is released: a query holding
// it may take the GIL (Model.sample of a strided array).
pyb::array_t<float> render(const Model* model, const Volume* volume, const RenderArgs& a, std::mutex* model_mutex) {
  const auto [w, h] = a.size;
  if (w < 1 || h < 1 || w > 32768 || h > 32768) fail("size expects (width, height), positive, at most 32768, got ({}, {})", w, h);
  if (a.spp < 0) fail("spp must be 'auto' or at least 1, got {}", a.spp);
  const Convergence converge{a.noise, 4, a.max_spp};
  if (!(converge.noise >= 0) || converge.max_frames < converge.min_frames)
    fail("noise must be at least 0 and max_spp at least {}, got {} and {}", converge.min_frames, a.noise, a.max_spp);
  if (a.device != "auto" && a.device != "cpu" && a.device != "cuda")
    fail("unknown device '{}' (allowed: auto, cpu, cuda)", a.device);
  RenderOptions o;
  o.mode = parse_render_mode(a.mode);
  o.width = w;
  o.height = h;
  o.step = a.step;
  o.seed = a.seed;
  o.shade = a.shade;
  if (a.light) o.light.direction = vec(*a.light);
  if (a.background) o.background = vec(*a.background);
  const TransferFunction tf = transfer_function_of(a.tf);
  pyb::array_t<float> out({pyb::ssize_t(h), pyb::ssize_t(w), pyb::ssize_t(4)});
  float* dst = out.mutable_data();
  pyb::gil_scoped_release release;
  std::unique_lock<std::mutex> lock;
  if (model_mutex) lock = std::unique_lock(*model_mutex);
  const MacroCellMode mc = a.macrocells ? parse_macrocell_mode(*a.macrocells) : default_macrocell_mode(model, volume);
  const Device device = choose_render_device(a.device, model);
  std::unique_ptr<Renderer> r = model ? std::make_unique<Renderer>(*model, device) : std::make_unique<Renderer>(*volume, device);
  r->set_scene(Scene{});
  r->set_transfer_function(tf);
  r->set_camera(camera_of(a, r->box()));
  r->set_options(o);
  Int3 cache_dims{0, 0, 0};
  if (a.cache_dims) {
    const auto [x, y, z] = *a.cache_dims;
    if (x < 1 || y < 1 || z < 1) fail("cache_dims expects (x, y, z), positive, got ({}, {}, {})", x, y, z);
    if (!model) fail("cache_dims is for models (a volume is drawn directly)");
    cache_dims = Int3{x, y, z};
  }
  r->choose_strategy(a.strategy, parse_cache_budget(a.cache_budget), cache_dims, a.spp);
  r->set_macrocells(mc, 16);
  r->prepare();
  r->warm_cache();
  if (a.spp == 0) r->render_until_converged(converge);
  for (int f = 0; f < a.spp; ++f) r->render_frame();
  const Image& img = r->image();
  std::memcpy(dst, img.pixels.data(), img.pixels.size() * sizeof(Vec4f));
  return out;
}

}  // namespace

void bind_render(pyb::module_& m) {
  m.def(
      "_render",
      [](pyb::object target, std::optional<Vec3> eye, std::optional<Vec3> center, Vec3 up, float fovy,
         std::optional<std::pair<float, float>> orbit, const std::string& tf, const std::string& mode,
         std::pair<int, int> size, int spp, double noise, int max_spp, const std::string& device,
         const std::string& strategy,
         std::optional<std::string> macrocells, float step, uint32_t seed, bool shade, std::optional<Vec3> background,
         std::optional<Vec3> light, const std::string& cache_budget,
         std::optional<std::tuple<int64_t, int64_t, int64_t>> cache_dims) {
        RenderArgs a{eye, center, up, fovy, orbit, tf, mode, strategy, device, macrocells, size, spp, noise, max_spp,
                     step, seed, shade, background, light, cache_budget, cache_dims};
        if (pyb::isinstance<ModelHolder>(target)) {
          ModelPtr h = target.cast<ModelPtr>();
          return render(&h->model, nullptr, a, &h->mutex);
        }
        if (pyb::isinstance<Volume>(target)) return render(nullptr, target.cast<std::shared_ptr<Volume>>().get(), a, nullptr);
        fail("render expects a vnr.Model or a vnr.Volume");
      },
      pyb::arg("target"), pyb::arg("eye"), pyb::arg("center"), pyb::arg("up"), pyb::arg("fovy"), pyb::arg("orbit"),
      pyb::arg("tf"), pyb::arg("mode"), pyb::arg("size"), pyb::arg("spp"), pyb::arg("noise"), pyb::arg("max_spp"),
      pyb::arg("device"), pyb::arg("strategy"),
      pyb::arg("macrocells"), pyb::arg("step"), pyb::arg("seed"), pyb::arg("shade"), pyb::arg("background"),
      pyb::arg("light"), pyb::arg("cache_budget"), pyb::arg("cache_dims"),
      "The renderer behind vnr.render (which documents the arguments).");
}

}  // namespace vnr::py
