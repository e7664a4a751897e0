// Scene files: instantvnr's scene JSON (unknown keys ignored,
// as instantvnr does) and vnr's own scene JSON (unknown keys are errors: typo safety).
#include "vnr/scene.h"
#include "vnr/render/camera.h"
#include <cmath>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/json.h"

namespace vnr {

namespace {

double finite_number(const Json& j, const std::string& where) {
  if (!j.is_number()) fail("{}: expected a number, got {}", where, j.type_name());
  const double v = j.get<double>();
  if (!std::isfinite(v)) fail("{}: number is not finite", where);
  return v;
}

// {"x": .., "y": .., "z": ..} (instantvnr)
Vec3f xyz_of(const Json& j, const std::string& where) {
  if (!j.is_object()) fail("{}: expected an object {{\"x\", \"y\", \"z\"}}, got {}", where, j.type_name());
  float v[3];
  const char* keys[3] = {"x", "y", "z"};
  for (int k = 0; k < 3; ++k) {
    auto it = j.find(keys[k]);
    if (it == j.end()) fail("{}: missing key \"{}\"", where, keys[k]);
    v[k] = float(finite_number(*it, where + "." + keys[k]));
  }
  return Vec3f{v[0], v[1], v[2]};
}

// [x, y, z] (vnr)
Vec3f array3_of(const Json& j, const std::string& where) {
  if (!j.is_array() || j.size() != 3) fail("{}: expected an array of 3 numbers", where);
  return Vec3f{float(finite_number(j[0], where + "[0]")), float(finite_number(j[1], where + "[1]")),
               float(finite_number(j[2], where + "[2]"))};
}

void check_camera(const Camera& cam, const std::string& where) {
  try {
    (void)make_camera_frame(cam, 1, 1);
  } catch (const Error& e) {
    fail("{}: {}", where, e.what());
  }
}

void check_keys(const Json& j, std::initializer_list<const char*> allowed, const std::string& where,
                const char* what) {
  for (auto it = j.begin(); it != j.end(); ++it) {
    bool ok = false;
    std::string list;
    for (const char* a : allowed) {
      ok = ok || it.key() == a;
      list += (list.empty() ? "" : ", ") + std::string(a);
    }
    if (!ok) fail("{}: unknown {} key \"{}\" (allowed: {})", where, what, it.key(), list);
  }
}

Scene load_instantvnr_scene(const Json& j, const std::string& path) {
  Scene s;
  std::string version = "VIDI3D";
  if (auto it = j.find("version"); it != j.end()) {
    if (!it->is_string()) fail("{}: \"version\" must be a string", path);
    version = it->get<std::string>();
    if (version != "VIDI3D" && version != "DIVA")
      fail("{}: unknown scene version \"{}\" (expected \"VIDI3D\" or \"DIVA\")", path, version);
  }
  if (version == "DIVA") {  // volume only: instantvnr implements neither camera nor TF for DIVA
    s.has_volume = j.contains("volume");
    return s;
  }
  if (auto it = j.find("dataSource"); it != j.end()) {
    if (!it->is_array()) fail("{}: \"dataSource\" must be an array", path);
    s.has_volume = !it->empty();
  }
  auto view = j.find("view");
  if (view == j.end()) return s;
  if (!view->is_object()) fail("{}: \"view\" must be an object", path);

  if (auto c = view->find("camera"); c != view->end()) {
    const std::string w = path + ": view.camera";
    if (!c->is_object()) fail("{}: expected an object", w);
    for (const char* k : {"eye", "center", "up", "fovy"})
      if (!c->contains(k)) fail("{}: missing key \"{}\"", w, k);
    // Voxel-index units with voxel centres on integers -> B.2 world (voxel i centre at i + 0.5).
    const Vec3f half{0.5f, 0.5f, 0.5f};
    Camera cam;
    cam.eye = xyz_of((*c)["eye"], w + ".eye") + half;
    cam.center = xyz_of((*c)["center"], w + ".center") + half;
    cam.up = xyz_of((*c)["up"], w + ".up");
    cam.fovy = float(finite_number((*c)["fovy"], w + ".fovy"));
    check_camera(cam, w);
    s.camera = cam;
  }
  if (auto vol = view->find("volume"); vol != view->end() && vol->is_object() && vol->contains("transferFunction")) {
    TransferFunction tf = tf_from_json(j, path);  // reads view.volume.transferFunction, window [0,1]
    tf.name = path;
    s.tf = std::move(tf);
  }
  return s;
}

Scene load_vnr_scene(const Json& j, const std::string& path) {
  check_keys(j, {"camera", "transfer_function", "light", "background"}, path, "scene");
  Scene s;
  if (auto c = j.find("camera"); c != j.end()) {
    const std::string w = path + ": camera";
    if (!c->is_object()) fail("{}: expected an object", w);
    check_keys(*c, {"eye", "center", "up", "fovy"}, w, "camera");
    for (const char* k : {"eye", "center"})
      if (!c->contains(k)) fail("{}: missing key \"{}\"", w, k);
    Camera cam;
    cam.eye = array3_of((*c)["eye"], w + ".eye");
    cam.center = array3_of((*c)["center"], w + ".center");
    if (c->contains("up")) cam.up = array3_of((*c)["up"], w + ".up");
    if (c->contains("fovy")) cam.fovy = float(finite_number((*c)["fovy"], w + ".fovy"));
    check_camera(cam, w);
    s.camera = cam;
  }
  if (auto t = j.find("transfer_function"); t != j.end()) {
    const std::string w = path + ": transfer_function";
    if (t->is_string()) {
      // A preset name, or a TF file relative to the scene file.
      const std::string name = t->get<std::string>();
      if (is_tf_preset(name)) {
        s.tf = tf_preset(name);
      } else {
        const std::string file = join_path(dirname_of(path), name);
        if (!file_exists(file)) {
          std::string list;
          for (const auto& p : tf_preset_names()) list += (list.empty() ? "" : ", ") + p;
          fail("{}: \"{}\" is neither a preset ({}) nor an existing file", w, name, list);
        }
        s.tf = load_transfer_function(file);
      }
    } else if (t->is_object()) {
      TransferFunction tf = tf_from_json(*t, w);
      tf.name = path;
      s.tf = std::move(tf);
    } else {
      fail("{}: expected a preset name, a file name or an object, got {}", w, t->type_name());
    }
  }
  if (auto l = j.find("light"); l != j.end()) {
    const std::string w = path + ": light";
    if (!l->is_object()) fail("{}: expected an object", w);
    check_keys(*l, {"direction", "color"}, w, "light");
    DirectionalLight light;
    if (l->contains("direction")) {
      const Vec3f d = array3_of((*l)["direction"], w + ".direction");
      if (!(length(d) > 0)) fail("{}.direction: must not be zero", w);
      light.direction = normalize(d);
    }
    if (l->contains("color")) {
      const Vec3f c = array3_of((*l)["color"], w + ".color");
      if (c.x < 0 || c.y < 0 || c.z < 0) fail("{}.color: components must not be negative", w);
      light.color = c;
    }
    s.light = light;
  }
  if (auto b = j.find("background"); b != j.end()) {
    const Vec3f c = array3_of(*b, path + ": background");
    if (c.x < 0 || c.y < 0 || c.z < 0) fail("{}: background: components must not be negative", path);
    s.background = c;
  }
  return s;
}

}  // namespace

Scene load_scene(const std::string& path) { return scene_from_json(parse_json_file(path), path); }

bool is_instantvnr_scene(const Json& j) { return j.contains("dataSource") || j.contains("view") || j.contains("version"); }

Scene scene_from_json(const Json& j, const std::string& path) {
  if (!j.is_object()) fail("{}: a scene must be a JSON object, got {}", path, j.type_name());
  if (is_instantvnr_scene(j)) return load_instantvnr_scene(j, path);
  return load_vnr_scene(j, path);
}

Json scene_to_instantvnr_json(const Camera& camera, const TransferFunction& tf) {
  auto xyz = [](Vec3f v) { return Json{{"x", v.x}, {"y", v.y}, {"z", v.z}}; };
  const Vec3f half{0.5f, 0.5f, 0.5f};
  Json cam = {{"eye", xyz(camera.eye - half)},
              {"center", xyz(camera.center - half)},
              {"up", xyz(camera.up)},
              {"fovy", camera.fovy},
              {"projectionMode", "PERSPECTIVE"}};
  Json volume = {{"transferFunction", tf_to_instantvnr_json(tf)["transferFunction"]},
                 {"transferFunctionType", "TRANSFER_FUNCTION"}};
  return Json{{"version", "VIDI3D"}, {"view", {{"camera", std::move(cam)}, {"volume", std::move(volume)}}}};
}

}  // namespace vnr
