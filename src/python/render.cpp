// vnr.render: one image of a model or a volume, set up by vnr::setup_renderer from vnr::RenderSettings,
// as `vnr render` sets it up: the same settings give the same image.
#include "bindings.h"
#include "vnr/error.h"
#include "vnr/json.h"

namespace vnr::py {

namespace {

// `model_mutex` (the model's holder's, or null) is locked only once the GIL is released: a query holding
// it may take the GIL (Model.sample of a strided array).
pyb::array_t<float> render(const Model* model, const Volume* volume, const RenderSettings& s, std::mutex* model_mutex) {
  // A transfer function file that is missing: FileNotFoundError, as for every other path the module opens.
  if (names_a_tf_file(s.tf)) require_file(s.tf, "transfer function");
  pyb::array_t<float> out({pyb::ssize_t(s.height), pyb::ssize_t(s.width), pyb::ssize_t(4)});
  float* dst = out.mutable_data();
  pyb::gil_scoped_release release;
  std::unique_lock<std::mutex> lock;
  if (model_mutex) lock = std::unique_lock(*model_mutex);
  RenderSetup setup = setup_renderer(model, volume, Scene{}, s);
  Renderer& r = *setup.renderer;
  r.prepare();
  r.warm_cache();
  if (s.spp == 0) r.render_until_converged(Convergence{s.noise, Convergence{}.min_frames, s.max_spp});
  for (int f = 0; f < s.spp; ++f) r.render_frame();
  const Image& img = r.image();
  std::memcpy(dst, img.pixels.data(), img.pixels.size() * sizeof(Vec4f));
  return out;
}

}  // namespace

void bind_render(pyb::module_& m) {
  m.def(
      "_render",
      [](pyb::object target, const std::string& settings_json) {
        const RenderSettings s = RenderSettings::from_json(parse_json_text(settings_json, "render settings"));
        if (pyb::isinstance<ModelHolder>(target)) {
          ModelPtr h = target.cast<ModelPtr>();
          return render(&h->model, nullptr, s, &h->mutex);
        }
        if (pyb::isinstance<Volume>(target)) return render(nullptr, target.cast<std::shared_ptr<Volume>>().get(), s, nullptr);
        fail("render expects a vnr.Model or a vnr.Volume");
      },
      pyb::arg("target"), pyb::arg("settings_json"),
      "The renderer behind vnr.render (which documents the settings): vnr::RenderSettings as JSON.");
}

}  // namespace vnr::py
