#pragma once
// Scene files: instantvnr's scene JSON (the instantvnr scene format) or vnr's own scene
// JSON. Everything is optional; the renderer fills in defaults (docs/semantics.md B.8, B.10).
#include <optional>
#include <string>
#include "vnr/camera.h"
#include "vnr/json.h"
#include "vnr/math.h"
#include "vnr/transfer_function.h"

namespace vnr {

// Directional light: `direction` points from the scene toward the light.
struct DirectionalLight {
  Vec3f direction = normalize(Vec3f{0.7f, 0.9f, 0.4f});
  Vec3f color{1, 1, 1};
};

struct Scene {
  std::optional<Camera> camera;          // world space of B.2
  std::optional<TransferFunction> tf;
  std::optional<DirectionalLight> light;
  std::optional<Vec3f> background;
  bool has_volume = false;               // an instantvnr scene names its volume (dataSource)
};

// instantvnr scenes: `view.camera` eye/center are in voxel-index units with voxel centres on
// integers; they are converted to B.2 world space by adding 0.5 per axis. The TF comes from
// `view.volume.transferFunction` (over the normalised range). vnr scenes:
// {"camera": {"eye": [x,y,z], "center": [...], "up": [...], "fovy": deg}, "transfer_function":
// <TF object or preset name>, "light": {"direction": [...], "color": [...]}, "background": [r,g,b]}.
Scene load_scene(const std::string& path);
// Whether parsed scene JSON is instantvnr's (it has "dataSource", "view" or "version"), else vnr's.
bool is_instantvnr_scene(const Json& j);
// The same from parsed JSON; `where` names it in errors and anchors a vnr scene's relative TF file.
Scene scene_from_json(const Json& j, const std::string& where);
// An instantvnr scene of a view: view.camera (converted back to voxel-index units: world - 0.5) and
// view.volume.transferFunction (tf_to_instantvnr_json); load_scene reads it back to the same camera
// and table. No dataSource: it names no volume.
Json scene_to_instantvnr_json(const Camera& camera, const TransferFunction& tf);

}  // namespace vnr
