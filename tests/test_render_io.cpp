// Render-layer I/O: cameras and scene files (transfer functions: test_transfer_function.cpp;
// images and image metrics: test_image_io.cpp).
#include <gtest/gtest.h>
#include <png.h>
#include <unistd.h>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <numbers>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/json.h"
#include "vnr/core/rng.h"
#include "vnr/render/camera.h"
#include "vnr/render/image.h"
#include "vnr/scene.h"
#include "vnr/render/transfer_function.h"
#include "test_support.h"

using namespace vnr;
using namespace vnr::test;

// ---- camera -------------------------------------------------------------------------------------

TEST(Camera, FrameIsOrthogonalWithFovSpan) {
  Camera cam;
  cam.eye = {10, 20, 30};
  cam.center = {1, 2, 3};
  cam.up = {0.1f, 1, 0.2f};
  cam.fovy = 40;
  CameraFrame f = make_camera_frame(cam, 300, 200);
  const float span = 2 * std::tan(20.0f * std::numbers::pi_v<float> / 180);
  EXPECT_NEAR(length(f.dir), 1, 1e-6);
  EXPECT_NEAR(length(f.dv), span, 1e-5);
  EXPECT_NEAR(length(f.du), span * 1.5f, 1e-5);
  EXPECT_NEAR(dot(f.dir, f.du), 0, 1e-5);
  EXPECT_NEAR(dot(f.dir, f.dv), 0, 1e-5);
  EXPECT_NEAR(dot(f.du, f.dv), 0, 1e-5);
  EXPECT_GT(dot(f.dv, cam.up), 0);  // dv points up
  Vec3f d = normalize(cam.center - cam.eye);
  EXPECT_NEAR(dot(f.dir, d), 1, 1e-6);
  // Right-handed: du = dir x up direction (looking down -z with +y up, du points to +x).
  CameraFrame g = make_camera_frame(Camera{}, 10, 10);
  EXPECT_GT(g.du.x, 0);
  EXPECT_GT(g.dv.y, 0);
  EXPECT_EQ(g.width, 10);
  EXPECT_EQ(g.height, 10);
}

TEST(Camera, CentrePixelOfOddImageLooksAlongDir) {
  Camera cam;
  cam.eye = {-3, 5, 7};
  cam.center = {2, -1, 0.5f};
  cam.up = {0, 0, 1};
  cam.fovy = 60;
  CameraFrame f = make_camera_frame(cam, 5, 3);
  Vec3f r = camera_ray_dir(f, 2, 1, 0.5f, 0.5f);
  EXPECT_NEAR(r.x, f.dir.x, 1e-6);
  EXPECT_NEAR(r.y, f.dir.y, 1e-6);
  EXPECT_NEAR(r.z, f.dir.z, 1e-6);
  // Row 0 is the top: the top-left corner ray leans up and left.
  Vec3f tl = camera_ray_dir(f, 0, 0, 0, 0);
  EXPECT_GT(dot(tl, f.dv), 0);
  EXPECT_LT(dot(tl, f.du), 0);
  // Vertical field of view: top and bottom edge rays of the centre column are fovy apart.
  Vec3f top = camera_ray_dir(f, 2, 0, 0.5f, 0), bottom = camera_ray_dir(f, 2, 2, 0.5f, 1);
  EXPECT_NEAR(std::acos(dot(top, bottom)) * 180 / std::numbers::pi, 60.0, 1e-3);
}

TEST(Camera, InvalidCamerasFail) {
  Camera c;
  c.eye = c.center = {1, 2, 3};
  expect_error([&] { make_camera_frame(c, 8, 8); }, {"same point"});
  c = Camera{};
  c.up = {0, 0, 2};  // parallel to the view direction (-z)
  expect_error([&] { make_camera_frame(c, 8, 8); }, {"parallel"});
  c.up = {0, 0, 0};
  expect_error([&] { make_camera_frame(c, 8, 8); }, {"up"});
  c = Camera{};
  for (float fov : {0.0f, 180.0f, -5.0f, 200.0f}) {
    c.fovy = fov;
    expect_error([&] { make_camera_frame(c, 8, 8); }, {"fovy"});
  }
  expect_error([&] { make_camera_frame(Camera{}, 0, 8); }, {"image size"});
  expect_error([&] { make_camera_frame(Camera{}, 8, -1); }, {"image size"});
}

TEST(Camera, OrbitFollowsVtkResetCamera) {
  const Vec3f box{64, 32, 16};
  const float r = 0.5f * std::sqrt(63.0f * 63 + 31 * 31 + 15 * 15);
  const float dist = r / std::sin(15.0f * std::numbers::pi_v<float> / 180);
  Camera c = orbit_camera(box, 0);
  EXPECT_FLOAT_EQ(c.fovy, 30);
  EXPECT_NEAR(c.center.x, 32, 1e-6);
  EXPECT_NEAR(c.center.y, 16, 1e-6);
  EXPECT_NEAR(c.center.z, 8, 1e-6);
  EXPECT_NEAR(c.eye.x, 32, 1e-4);
  EXPECT_NEAR(c.eye.y, 16, 1e-4);
  EXPECT_NEAR(c.eye.z, 8 + dist, 1e-3);
  EXPECT_NEAR(c.up.y, 1, 1e-6);
  // Azimuth 90 puts the camera on +x; the distance stays the same.
  Camera a = orbit_camera(box, 90);
  EXPECT_NEAR(a.eye.x, 32 + dist, 1e-3);
  EXPECT_NEAR(a.eye.z, 8, 1e-3);
  // Elevation lifts the camera; distance and a valid frame hold even at 90 degrees.
  for (float el : {30.0f, 90.0f, -90.0f}) {
    Camera e = orbit_camera(box, 45, el, 45);
    EXPECT_NEAR(length(e.eye - e.center), 0.5f * std::sqrt(63.0f * 63 + 31 * 31 + 15 * 15) /
                                              std::sin(22.5f * std::numbers::pi_v<float> / 180),
                1e-3);
    EXPECT_NEAR(e.eye.y - e.center.y, std::sin(el * std::numbers::pi_v<float> / 180) * length(e.eye - e.center), 1e-3);
    CameraFrame f = make_camera_frame(e, 4, 4);
    EXPECT_NEAR(dot(f.dir, f.dv), 0, 1e-5);
  }
  expect_error([&] { orbit_camera(Vec3f{0, 1, 1}, 0); }, {"box"});
}

// ---- scenes -------------------------------------------------------------------------------------

TEST(Scene, VnrSceneFile) {
  TmpDir dir;
  const std::string path = dir / "scene.json";
  write_bytes(path, R"({
    // vnr scene with comments
    "camera": {"eye": [1, 2, 30], "center": [1, 2, 3], "fovy": 35},
    "transfer_function": "cool-warm",
    "light": {"direction": [0, 2, 0], "color": [0.5, 0.5, 1]},
    "background": [0.1, 0.2, 0.3]
  })");
  Scene s = load_scene(path);
  ASSERT_TRUE(s.camera && s.tf && s.light && s.background);
  EXPECT_FALSE(s.has_volume);
  EXPECT_FLOAT_EQ(s.camera->eye.z, 30);
  EXPECT_FLOAT_EQ(s.camera->up.y, 1);  // default
  EXPECT_FLOAT_EQ(s.camera->fovy, 35);
  EXPECT_EQ(s.tf->name, "cool-warm");
  EXPECT_FLOAT_EQ(s.light->direction.y, 1);  // normalised
  EXPECT_FLOAT_EQ(s.light->color.z, 1);
  EXPECT_FLOAT_EQ(s.background->y, 0.2f);

  // Inline TF object; a TF file named relative to the scene.
  write_bytes(dir / "tf.json", R"({"colors": [[0, 1, 0, 0]], "opacities": [[0, 0.5]], "resolution": 3})");
  write_bytes(dir / "s2.json", R"({"transfer_function": "tf.json"})");
  Scene s2 = load_scene(dir / "s2.json");
  ASSERT_TRUE(s2.tf);
  EXPECT_EQ(s2.tf->table.size(), 3u);
  EXPECT_FALSE(s2.camera);
  write_bytes(dir / "s3.json", R"({"transfer_function": {"colors": [[0, 1, 0, 0]], "opacities": [[0, 0.25]]}})");
  Scene s3 = load_scene(dir / "s3.json");
  EXPECT_FLOAT_EQ(s3.tf->table[5].w, 0.25f);
  // An empty object is a valid scene with nothing set.
  write_bytes(dir / "empty.json", "{}");
  Scene e = load_scene(dir / "empty.json");
  EXPECT_FALSE(e.camera || e.tf || e.light || e.background);
}

TEST(Scene, ErrorsNameTheFileAndKey) {
  TmpDir dir;
  auto scene_error = [&](const std::string& name, const std::string& text, std::initializer_list<const char*> frags) {
    write_bytes(dir / name, text);
    expect_error([&] { load_scene(dir / name); }, frags);
  };
  scene_error("typo.json", R"({"camrea": {}})", {"typo.json", "camrea", "unknown"});
  scene_error("camkey.json", R"({"camera": {"eye": [0,0,1], "center": [0,0,0], "fov": 40}})", {"camkey.json", "\"fov\""});
  scene_error("same.json", R"({"camera": {"eye": [1,1,1], "center": [1,1,1]}})", {"same.json", "same point"});
  scene_error("noeye.json", R"({"camera": {"center": [1,1,1]}})", {"noeye.json", "eye"});
  scene_error("vec.json", R"({"background": [1, 2]})", {"vec.json", "background", "3 numbers"});
  scene_error("tfname.json", R"({"transfer_function": "rmap"})", {"tfname.json", "rmap", "ramp"});
  scene_error("badtf.json", R"({"transfer_function": {"colors": [[0, 1, 0, 0]], "opacities": [[0, 2]]}})",
              {"badtf.json", "transfer_function", "[0, 1]"});
  scene_error("arr.json", "[1, 2]", {"arr.json", "object"});
  scene_error("syntax.json", "{\"camera\": ", {"syntax.json", "invalid JSON"});
  scene_error("light.json", R"({"light": {"direction": [0, 0, 0]}})", {"light.json", "direction"});
  // instantvnr scenes: unknown keys are ignored, camera errors still name the file.
  write_bytes(dir / "iv.json", R"({"dataSource": [{"format": "REGULAR_GRID_RAW_BINARY"}], "whatever": 1,
      "view": {"zoom": 3, "camera": {"eye": {"x": 0, "y": 0, "z": 10}, "center": {"x": 0, "y": 0, "z": 0},
      "up": {"x": 0, "y": 1, "z": 0}, "fovy": 45, "zNear": 1}}})");
  Scene iv = load_scene(dir / "iv.json");
  EXPECT_TRUE(iv.has_volume);
  EXPECT_FLOAT_EQ(iv.camera->eye.z, 10.5f);
  EXPECT_FALSE(iv.tf);
  scene_error("ivbad.json", R"({"view": {"camera": {"eye": {"x": 0, "y": 0, "z": 10}, "center": {"x": 0, "y": 0},
      "up": {"x": 0, "y": 1, "z": 0}, "fovy": 45}}})",
              {"ivbad.json", "view.camera.center", "\"z\""});
  scene_error("ivfov.json", R"({"view": {"camera": {"eye": {"x": 0, "y": 0, "z": 10}, "center": {"x": 0, "y": 0, "z": 0},
      "up": {"x": 0, "y": 1, "z": 0}, "fovy": 190}}})",
              {"ivfov.json", "fovy"});
  scene_error("ver.json", R"({"version": "X", "view": {}})", {"ver.json", "version"});
  expect_error([&] { load_scene(dir / "nope.json"); }, {"nope.json", "cannot open"});
}
