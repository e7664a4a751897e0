// Render-layer I/O: cameras, transfer functions, images and scene files.
#include <gtest/gtest.h>
#include <png.h>
#include <unistd.h>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <numbers>
#include "vnr/core/error.h"
#include "vnr/core/fileio.h"
#include "vnr/core/json.h"
#include "vnr/core/rng.h"
#include "vnr/render/camera.h"
#include "vnr/render/image.h"
#include "vnr/render/scene.h"
#include "vnr/render/transfer_function.h"
#include "test_support.h"

using namespace vnr;
using namespace vnr::test;

namespace {

std::string base64_encode(const std::string& in) {
  static const char* A = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  size_t i = 0;
  for (; i + 3 <= in.size(); i += 3) {
    uint32_t v = uint32_t(uint8_t(in[i])) << 16 | uint32_t(uint8_t(in[i + 1])) << 8 | uint8_t(in[i + 2]);
    for (int k = 3; k >= 0; --k) out += A[(v >> (6 * k)) & 63];
  }
  if (in.size() - i == 1) {
    uint32_t v = uint32_t(uint8_t(in[i])) << 16;
    out += A[(v >> 18) & 63];
    out += A[(v >> 12) & 63];
    out += "==";
  } else if (in.size() - i == 2) {
    uint32_t v = uint32_t(uint8_t(in[i])) << 16 | uint32_t(uint8_t(in[i + 1])) << 8;
    out += A[(v >> 18) & 63];
    out += A[(v >> 12) & 63];
    out += A[(v >> 6) & 63];
    out += '=';
  }
  return out;
}

std::string floats_le(const std::vector<float>& v) {
  std::string s(v.size() * 4, '\0');
  for (size_t i = 0; i < v.size(); ++i) {
    uint32_t u;
    std::memcpy(&u, &v[i], 4);
    for (int b = 0; b < 4; ++b) s[4 * i + b] = char((u >> (8 * b)) & 0xff);
  }
  return s;
}

Json alpha_array_json(const std::string& bytes) {
  return Json{{"encoding", "BASE64"}, {"data", base64_encode(bytes)}};
}

std::string example(const std::string& name) {
  return std::string(VNR_SHARED_DIR) + "/reference/instantvnr-formats/examples/" + name;
}

float lookup_a(const TransferFunction& tf, float u) { return tf_lookup(view_of(tf), u).w; }

Image random_image(int w, int h, uint64_t seed, float lo = 0, float hi = 1) {
  Pcg32 rng(seed);
  Image img(w, h);
  for (auto& p : img.pixels)
    p = Vec4f{lo + (hi - lo) * rng.next_float(), lo + (hi - lo) * rng.next_float(), lo + (hi - lo) * rng.next_float(), 1};
  return img;
}

}  // namespace

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

// ---- transfer functions -------------------------------------------------------------------------

TEST(TransferFunction, RampPresetMatchesVtkPeer) {
  TransferFunction tf = tf_preset("ramp");
  ASSERT_EQ(tf.table.size(), 1024u);
  EXPECT_EQ(tf.name, "ramp");
  EXPECT_EQ(tf.lo, 0);
  EXPECT_EQ(tf.hi, 1);
  // Table entries at i/(N-1): the ends are the control points exactly.
  EXPECT_FLOAT_EQ(tf.table[0].x, 0);
  EXPECT_FLOAT_EQ(tf.table[0].z, 0.3f);
  EXPECT_FLOAT_EQ(tf.table[0].w, 0);
  EXPECT_FLOAT_EQ(tf.table[1023].x, 1);
  EXPECT_FLOAT_EQ(tf.table[1023].z, 0.9f);
  EXPECT_FLOAT_EQ(tf.table[1023].w, 0.8f);
  // Opacity: 0 up to 0.1, then linear to 0.8 at 1 (up to the half-entry kink at 0.1).
  EXPECT_EQ(lookup_a(tf, 0.05f), 0);
  EXPECT_NEAR(lookup_a(tf, 0.1f), 0, 1e-3);
  EXPECT_NEAR(lookup_a(tf, 0.55f), 0.4f, 1e-5);
  EXPECT_NEAR(lookup_a(tf, 1.0f), 0.8f, 1e-6);
  for (int i = 0; i < 1024; ++i) {
    const double x = i / 1023.0;
    EXPECT_NEAR(tf.table[size_t(i)].w, x <= 0.1 ? 0.0 : (x - 0.1) / 0.9 * 0.8, 1e-6) << i;
  }
  // Colour at the middle control point.
  Vec4f c = tf_lookup(view_of(tf), 0.3f);
  EXPECT_NEAR(c.x, 0.9f, 2e-3);
  EXPECT_NEAR(c.y, 0.4f, 2e-3);
  EXPECT_NEAR(c.z, 0.1f, 2e-3);
  // Halfway along the second segment.
  c = tf_lookup(view_of(tf), 0.65f);
  EXPECT_NEAR(c.x, 0.95f, 1e-4);
  EXPECT_NEAR(c.y, 0.7f, 1e-4);
  EXPECT_NEAR(c.z, 0.5f, 1e-4);
}

TEST(TransferFunction, LookupInterpolatesAndClamps) {
  TransferFunction tf;
  tf.table = {Vec4f{0, 0, 0, 0}, Vec4f{1, 0.5f, 0, 0.2f}, Vec4f{1, 1, 1, 1}};
  TfView v = view_of(tf);
  EXPECT_FLOAT_EQ(tf_lookup(v, 0.25f).x, 0.5f);
  EXPECT_FLOAT_EQ(tf_lookup(v, 0.25f).w, 0.1f);
  EXPECT_FLOAT_EQ(tf_lookup(v, 0.5f).y, 0.5f);
  EXPECT_FLOAT_EQ(tf_lookup(v, 0.75f).w, 0.6f);
  EXPECT_FLOAT_EQ(tf_lookup(v, 1.0f).w, 1.0f);
  EXPECT_FLOAT_EQ(tf_lookup(v, 7.0f).w, 1.0f);
  EXPECT_FLOAT_EQ(tf_lookup(v, -3.0f).w, 0.0f);
  // A window [0.2, 0.6] maps onto the table.
  tf.lo = 0.2f;
  tf.hi = 0.6f;
  v = view_of(tf);
  EXPECT_NEAR(tf_lookup(v, 0.4f).w, 0.2f, 1e-6);
  EXPECT_NEAR(tf_lookup(v, 0.5f).w, 0.6f, 1e-6);
  EXPECT_FLOAT_EQ(tf_lookup(v, 0.1f).w, 0.0f);
  EXPECT_FLOAT_EQ(tf_lookup(v, 0.9f).w, 1.0f);
}

TEST(TransferFunction, PresetsByName) {
  auto names = tf_preset_names();
  ASSERT_GE(names.size(), 4u);
  EXPECT_EQ(names[0], "ramp");
  for (const auto& n : names) {
    EXPECT_TRUE(is_tf_preset(n));
    TransferFunction tf = tf_preset(n);
    EXPECT_EQ(tf.table.size(), 1024u) << n;
    for (const Vec4f& e : tf.table) {
      for (float c : {e.x, e.y, e.z, e.w}) {
        EXPECT_GE(c, 0) << n;
        EXPECT_LE(c, 1) << n;
      }
    }
    EXPECT_EQ(load_transfer_function(n).table.size(), 1024u);
  }
  EXPECT_TRUE(is_tf_preset("RAMP"));
  EXPECT_FALSE(is_tf_preset("rampp"));
  expect_error([] { tf_preset("nope"); }, {"nope", "ramp", "gray"});
  expect_error([] { load_transfer_function("/nonexistent/tf.json"); }, {"/nonexistent/tf.json", "ramp", "preset"});
}

TEST(TransferFunction, InstantvnrBuildRules) {
  // Colour at (i+0.5)/N, opacityControl at i/(N-1), alpha = max, ends zeroed when < 0.01.
  const int n = 8;
  Json j = {{"resolution", n},
            {"colorControls",
             {{{"position", 0.75}, {"color", {{"r", 1}, {"g", 0}, {"b", 0.5}}}},
              {{"position", 0.25}, {"color", {{"r", 0}, {"g", 1}, {"b", 0.5}}}}}},
            {"opacityControl", {{{"position", {{"x", 0.0}, {"y", 0.0}}}}, {{"position", {{"x", 1.0}, {"y", 0.7}}}}}},
            {"gaussianObjects", {{{"mean", 0.5}, {"sigma", 0.1}, {"heightFactor", 0.1}}}}};
  TransferFunction tf = tf_from_json(j, "inline");
  ASSERT_EQ(tf.table.size(), size_t(n));
  EXPECT_EQ(tf.lo, 0);
  EXPECT_EQ(tf.hi, 1);
  for (int i = 0; i < n; ++i) {
    const double xc = (i + 0.5) / n, xn = double(i) / (n - 1);
    const double t = std::clamp((xc - 0.25) / 0.5, 0.0, 1.0);  // controls sorted: 0.25 green, 0.75 red
    EXPECT_NEAR(tf.table[i].x, t, 1e-6) << i;
    EXPECT_NEAR(tf.table[i].y, 1 - t, 1e-6) << i;
    EXPECT_NEAR(tf.table[i].z, 0.5, 1e-6) << i;
    const double g = std::clamp(0.1 / (0.1 * std::sqrt(2 * std::numbers::pi)) * std::exp(-(xc - 0.5) * (xc - 0.5) / 0.02), 0.0, 1.0);
    double a = std::max(g, 0.7 * xn);
    if ((i == 0 || i == n - 1) && a < 0.01) a = 0;
    EXPECT_NEAR(tf.table[i].w, a, 1e-6) << i;
  }
  // No colour controls: black.
  TransferFunction black = tf_from_json(Json{{"resolution", 4}, {"colorControls", Json::array()},
                                             {"gaussianObjects", Json::array()}},
                                        "x");
  EXPECT_EQ(black.table.size(), 4u);
  EXPECT_EQ(black.table[2].x, 0);
  EXPECT_EQ(black.table[2].w, 0);
}

TEST(TransferFunction, Base64AlphaArrayRoundTrip) {
  TmpDir dir;
  const std::vector<float> alpha = {0.5f, 0.001f, 0.25f, 1.0f, 0.005f};  // last entry < 0.01 -> 0
  Json tfj = {{"resolution", 1024},  // overridden by the alphaArray length
              {"alphaArray", alpha_array_json(floats_le(alpha))},
              {"colorControls", {{{"position", 0.0}, {"color", {{"r", 0.2}, {"g", 0.4}, {"b", 0.6}}}}}}};
  // The standalone instantvnr TF file: {"transferFunction": {...}}, written with a comment.
  const std::string path = dir / "tf.json";
  write_bytes(path, "// saved by the TF widget\n" + Json{{"transferFunction", tfj}}.dump(1));
  TransferFunction tf = load_transfer_function(path);
  ASSERT_EQ(tf.table.size(), alpha.size());
  EXPECT_EQ(tf.name, path);
  EXPECT_EQ(tf.table[0].w, 0.5f);  // >= 0.01: kept
  EXPECT_EQ(tf.table[1].w, 0.001f);
  EXPECT_EQ(tf.table[2].w, 0.25f);
  EXPECT_EQ(tf.table[3].w, 1.0f);
  EXPECT_EQ(tf.table[4].w, 0.0f);  // end entry below 0.01: zeroed
  EXPECT_FLOAT_EQ(tf.table[2].y, 0.4f);  // constant extension of the single colour control
  // The TF object on its own and a whole scene give the same table.
  TransferFunction direct = tf_from_json(tfj, "obj");
  Json scene = {{"dataSource", Json::array()}, {"view", {{"volume", {{"transferFunction", tfj}}}}}};
  TransferFunction from_scene = tf_from_json(scene, "scene");
  for (size_t i = 0; i < alpha.size(); ++i) {
    EXPECT_EQ(direct.table[i].w, tf.table[i].w);
    EXPECT_EQ(from_scene.table[i].w, tf.table[i].w);
  }
  // A first entry below 0.01 is zeroed too; unpadded base64 is accepted, whitespace ignored.
  std::string b64 = base64_encode(floats_le({0.009f, 0.3f, 0.4f}));
  while (!b64.empty() && b64.back() == '=') b64.pop_back();
  b64.insert(4, "\n ");
  TransferFunction t2 = tf_from_json(Json{{"alphaArray", {{"encoding", "BASE64"}, {"data", b64}}}}, "t2");
  ASSERT_EQ(t2.table.size(), 3u);
  EXPECT_EQ(t2.table[0].w, 0);
  EXPECT_EQ(t2.table[1].w, 0.3f);
  EXPECT_EQ(t2.table[2].w, 0.4f);
}

TEST(TransferFunction, VnrSimpleFormat) {
  Json j = {{"colors", {{1.0, 1, 1, 1}, {0.0, 0, 0, 0}}}, {"opacities", {{0.5, 0.0}, {1.0, 0.8}}}, {"resolution", 5},
            {"range", {0.2, 0.6}}};
  TransferFunction tf = tf_from_json(j, "simple");
  ASSERT_EQ(tf.table.size(), 5u);
  EXPECT_FLOAT_EQ(tf.lo, 0.2f);
  EXPECT_FLOAT_EQ(tf.hi, 0.6f);
  const float expect_a[5] = {0, 0, 0, 0.4f, 0.8f};
  for (int i = 0; i < 5; ++i) {
    EXPECT_NEAR(tf.table[i].x, i / 4.0, 1e-6);
    EXPECT_NEAR(tf.table[i].w, expect_a[i], 1e-6);
  }
  // u = 0.5 is 3/4 of the way through the window: entry 3.
  EXPECT_NEAR(tf_lookup(view_of(tf), 0.5f).w, 0.4f, 1e-6);
}

TEST(TransferFunction, ErrorsAreClear) {
  auto ivnr_alpha = [](const std::string& data) {
    return Json{{"alphaArray", {{"encoding", "BASE64"}, {"data", data}}}};
  };
  expect_error([] { tf_from_json(Json::array(), "w"); }, {"w", "object"});
  expect_error([&] { tf_from_json(ivnr_alpha("AAAA!AAA"), "bad.json"); }, {"bad.json", "alphaArray", "invalid base64", "'!'"});
  expect_error([&] { tf_from_json(ivnr_alpha("AAAAA"), "t"); }, {"invalid base64"});
  expect_error([&] { tf_from_json(ivnr_alpha("AA==AA=="), "t"); }, {"invalid base64"});
  expect_error([&] { tf_from_json(ivnr_alpha(base64_encode(std::string(6, '\0'))), "t"); }, {"float32"});
  expect_error([&] { tf_from_json(ivnr_alpha(base64_encode(std::string(4, '\0'))), "t"); }, {"at least 2"});
  expect_error([&] { tf_from_json(ivnr_alpha(base64_encode(floats_le({0.1f, NAN}))), "t"); }, {"entry 1", "not finite"});
  expect_error([&] { tf_from_json(ivnr_alpha(base64_encode(floats_le({0.1f, 1.5f}))), "t"); }, {"entry 1", "[0, 1]"});
  expect_error([] { tf_from_json(Json{{"alphaArray", {{"encoding", "HEX"}, {"data", ""}}}}, "t"); }, {"HEX", "BASE64"});
  expect_error([] { tf_from_json(Json{{"alphaArray", {{"encoding", "BASE64"}}}}, "t"); }, {"missing key \"data\""});
  expect_error([] { tf_from_json(Json{{"gaussianObjects", {{{"mean", 0.5}, {"heightFactor", 1}}}}}, "t"); },
               {"gaussianObjects[0]", "missing key \"sigma\""});
  expect_error([] { tf_from_json(Json{{"gaussianObjects", {{{"mean", 0.5}, {"sigma", 0}, {"heightFactor", 1}}}}}, "t"); },
               {"sigma", "positive"});
  expect_error([] { tf_from_json(Json{{"colorControls", {{{"position", 1.5}, {"color", {{"r", 0}, {"g", 0}, {"b", 0}}}}}}}, "t"); },
               {"colorControls[0].position", "[0, 1]"});
  expect_error([] { tf_from_json(Json{{"colorControls", {{{"position", 0.5}, {"color", {{"r", 0}, {"g", 0}}}}}}}, "t"); },
               {"missing key \"b\""});
  expect_error([] { tf_from_json(Json{{"resolution", 1}, {"colorControls", Json::array()}}, "t"); }, {"resolution", "[2, 65536]"});
  expect_error([] { tf_from_json(Json{{"resolution", 70000}, {"colorControls", Json::array()}}, "t"); }, {"resolution"});
  expect_error([] { tf_from_json(Json{{"resolution", 2.5}, {"colorControls", Json::array()}}, "t"); }, {"integer"});
  Json simple = {{"colors", {{0.0, 0, 0, 0}}}, {"opacities", {{0.0, 0.1}}}};
  Json bad = simple;
  bad["range"] = {0.5, 0.5};
  expect_error([&] { tf_from_json(bad, "t"); }, {"range", "below"});
  bad = simple;
  bad["colours"] = 1;
  expect_error([&] { tf_from_json(bad, "t"); }, {"unknown", "colours"});
  bad = simple;
  bad["opacities"] = {{0.0, 1.2}};
  expect_error([&] { tf_from_json(bad, "t"); }, {"opacities[0]", "[0, 1]"});
  bad = simple;
  bad.erase("colors");
  expect_error([&] { tf_from_json(bad, "t"); }, {"missing key \"colors\""});
  expect_error([] { tf_from_json(Json{{"foo", 1}}, "t"); }, {"not a transfer function", "foo"});
  expect_error([] { tf_from_json(Json{{"view", Json::object()}}, "s.json"); }, {"s.json", "view.volume.transferFunction"});
  TmpDir dir;
  write_bytes(dir / "broken.json", "{\"colors\": [");
  expect_error([&] { load_transfer_function(dir / "broken.json"); }, {"broken.json", "invalid JSON"});
}

TEST(TransferFunction, InstantvnrExampleScenes) {
  if (!file_exists(example("scene_skull.json"))) GTEST_SKIP() << "../shared/reference absent";
  // skull: an all-zero alphaArray plus two Gaussians.
  {
    TransferFunction tf = load_transfer_function(example("scene_skull.json"));
    ASSERT_EQ(tf.table.size(), 1024u);
    const double g[2][3] = {{0.4992389678955078, 0.12633180618286133, 0.35474708676338196},
                            {0.40943682193756104, 0.1339421570301056, 0.06959233433008194}};
    auto gauss = [&](int k, double x) {
      const double d = x - g[k][0];
      return std::clamp(g[k][2] / (g[k][1] * std::sqrt(2 * std::numbers::pi)) * std::exp(-d * d / (2 * g[k][1] * g[k][1])),
                        0.0, 1.0);
    };
    for (int i = 0; i < 1024; ++i) {
      const double x = (i + 0.5) / 1024;
      double a = std::max(gauss(0, x), gauss(1, x));
      if ((i == 0 || i == 1023) && a < 0.01) a = 0;
      ASSERT_NEAR(tf.table[i].w, a, 1e-6) << i;
    }
    const int at_mean = int(0.4992389678955078 * 1024);  // x_i within half an entry of the mean
    EXPECT_NEAR(tf.table[at_mean].w, std::min(1.0, 0.35474708676338196 / (0.12633180618286133 * std::sqrt(2 * std::numbers::pi))),
                1e-4);
  }
  // vorts1: the alphaArray itself (values checked with Python's base64 + struct).
  {
    Scene s = load_scene(example("scene_vorts1.json"));
    ASSERT_TRUE(s.tf.has_value());
    ASSERT_EQ(s.tf->table.size(), 1024u);
    EXPECT_EQ(s.tf->table[0].w, 0);  // 1.9e-6 < 0.01: zeroed
    EXPECT_EQ(s.tf->table[1].w, 2.0047086763952393e-06f);
    EXPECT_EQ(s.tf->table[1023].w, 0);
    float mx = 0;
    for (const auto& e : s.tf->table) mx = std::max(mx, e.w);
    EXPECT_EQ(mx, 0.49999403953552246f);
    // First colour control (0, 0.3647, 1) at position 0, second (0, 1, 0.9765) at 1/6: entry 0 at x = 0.5/1024.
    const double t = (0.5 / 1024) / 0.1666666716337204;
    EXPECT_NEAR(s.tf->table[0].y, 0.36470600962638855 + t * (1 - 0.36470600962638855), 1e-6);
    EXPECT_TRUE(s.has_volume);
    ASSERT_TRUE(s.camera.has_value());
    EXPECT_FLOAT_EQ(s.camera->eye.x, 64);
    EXPECT_FLOAT_EQ(s.camera->eye.z, 400.5f);
    EXPECT_FLOAT_EQ(s.camera->center.y, 64);  // (dims - 1) / 2 + 0.5 = the B.2 box centre
    EXPECT_FLOAT_EQ(s.camera->up.y, 1);
    EXPECT_FLOAT_EQ(s.camera->fovy, 45);
    EXPECT_FALSE(s.light.has_value());  // instantvnr ignores lightSource
    EXPECT_FALSE(s.background.has_value());
  }
  // engine and chameleon (which has // comment blocks) parse; chameleon's camera uses fovy 60.
  for (const char* name : {"scene_engine.json", "scene_chameleon.json"}) {
    Scene s = load_scene(example(name));
    EXPECT_TRUE(s.has_volume) << name;
    ASSERT_TRUE(s.camera.has_value()) << name;
    ASSERT_TRUE(s.tf.has_value()) << name;
    EXPECT_EQ(s.tf->table.size(), 1024u);
    EXPECT_NO_THROW(make_camera_frame(*s.camera, 64, 64));
  }
  Scene ch = load_scene(example("scene_chameleon.json"));
  EXPECT_FLOAT_EQ(ch.camera->fovy, 60);
  EXPECT_FLOAT_EQ(ch.camera->center.x, 512);
}

// ---- images -------------------------------------------------------------------------------------

TEST(Image, PngRoundTripWithin8Bits) {
  TmpDir dir;
  Image img = random_image(37, 23, 5, -0.2f, 1.2f);  // out-of-range values clamp
  img.at(0, 0) = Vec4f{NAN, 1.0f / 255, 254.0f / 255, 0.5f};
  const std::string path = dir / "a.png";
  write_image(path, img);
  Image back = read_image(path);
  ASSERT_EQ(back.width, 37);
  ASSERT_EQ(back.height, 23);
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const Vec4f a = img.at(x, y), b = back.at(x, y);
      const float ca[3] = {a.x, a.y, a.z}, cb[3] = {b.x, b.y, b.z};
      for (int k = 0; k < 3; ++k) {
        const float want = std::isnan(ca[k]) ? 0.0f : std::clamp(ca[k], 0.0f, 1.0f);
        ASSERT_NEAR(cb[k], want, 0.5f / 255 + 1e-6f) << x << "," << y;
      }
      EXPECT_EQ(b.w, 1.0f);
    }
  EXPECT_EQ(back.at(0, 0).y, 1.0f / 255);
  EXPECT_EQ(back.at(0, 0).z, 254.0f / 255);
  // 8-bit RGB with an sRGB chunk, row 0 at the top.
  const std::string bytes = read_file(path);
  EXPECT_NE(bytes.find("sRGB"), std::string::npos);
  EXPECT_EQ(uint8_t(bytes[24]), 8);  // IHDR bit depth
  EXPECT_EQ(uint8_t(bytes[25]), 2);  // IHDR colour type RGB
  EXPECT_FALSE(file_exists(path + ".tmp-" + std::to_string(::getpid())));
}

TEST(Image, PngReadsOtherPixelFormats) {
  TmpDir dir;
  // 16-bit grey, written with libpng's simplified API.
  {
    const int w = 5, h = 2;
    std::vector<uint16_t> px(w * h);
    for (int i = 0; i < w * h; ++i) px[i] = uint16_t(i * 6553 + 1);
    png_image im{};
    im.version = PNG_IMAGE_VERSION;
    im.width = w;
    im.height = h;
    im.format = PNG_FORMAT_LINEAR_Y;
    ASSERT_TRUE(png_image_write_to_file(&im, (dir / "g16.png").c_str(), 0, px.data(), 0, nullptr));
    Image img = read_image(dir / "g16.png");
    ASSERT_EQ(img.width, w);
    ASSERT_EQ(img.height, h);
    for (int i = 0; i < w * h; ++i) {
      EXPECT_FLOAT_EQ(img.pixels[i].x, px[i] / 65535.0f) << i;
      EXPECT_FLOAT_EQ(img.pixels[i].z, px[i] / 65535.0f) << i;
    }
  }
  // 8-bit RGBA: alpha ignored.
  {
    const uint8_t px[8] = {10, 20, 30, 0, 200, 100, 50, 128};
    png_image im{};
    im.version = PNG_IMAGE_VERSION;
    im.width = 2;
    im.height = 1;
    im.format = PNG_FORMAT_RGBA;
    ASSERT_TRUE(png_image_write_to_file(&im, (dir / "rgba.png").c_str(), 0, px, 0, nullptr));
    Image img = read_image(dir / "rgba.png");
    EXPECT_FLOAT_EQ(img.at(1, 0).x, 200.0f / 255);
    EXPECT_FLOAT_EQ(img.at(0, 0).z, 30.0f / 255);
    EXPECT_EQ(img.at(0, 0).w, 1.0f);
  }
  // Palette.
  {
    const uint8_t cmap[6] = {255, 0, 0, 0, 0, 255};
    const uint8_t idx[4] = {0, 1, 1, 0};
    png_image im{};
    im.version = PNG_IMAGE_VERSION;
    im.width = 2;
    im.height = 2;
    im.format = PNG_FORMAT_RGB_COLORMAP;
    im.colormap_entries = 2;
    ASSERT_TRUE(png_image_write_to_file(&im, (dir / "pal.png").c_str(), 0, idx, 0, cmap));
    Image img = read_image(dir / "pal.png");
    EXPECT_EQ(img.at(0, 0).x, 1.0f);
    EXPECT_EQ(img.at(1, 0).z, 1.0f);
    EXPECT_EQ(img.at(1, 0).x, 0.0f);
    EXPECT_EQ(img.at(0, 1).z, 1.0f);
  }
}

TEST(Image, PfmRoundTripIsExact) {
  TmpDir dir;
  Image img = random_image(5, 3, 11, -2, 3);
  img.at(0, 2) = Vec4f{1e-30f, -0.0f, 12345.678f, 1};
  const std::string path = dir / "a.pfm";
  write_image(path, img);
  Image back = read_image(path);
  ASSERT_EQ(back.width, 5);
  ASSERT_EQ(back.height, 3);
  for (size_t i = 0; i < img.pixels.size(); ++i) {
    EXPECT_EQ(std::memcmp(&back.pixels[i], &img.pixels[i], 12), 0) << i;
    EXPECT_EQ(back.pixels[i].w, 1.0f);
  }
  // Layout: header, then rows bottom to top, little-endian.
  const std::string bytes = read_file(path);
  const std::string header = "PF\n5 3\n-1.0\n";
  ASSERT_EQ(bytes.substr(0, header.size()), header);
  ASSERT_EQ(bytes.size(), header.size() + 5 * 3 * 12);
  float first;
  std::memcpy(&first, bytes.data() + header.size(), 4);
  EXPECT_EQ(first, img.at(0, 2).x);  // bottom-left pixel first
}

TEST(Image, PfmReadsBigEndianAndGreyscale) {
  TmpDir dir;
  // Big-endian "Pf" 2x2 greyscale: file rows bottom to top.
  const float vals[4] = {0.25f, 0.5f, 0.75f, 1.5f};  // bottom row (0.25, 0.5), top row (0.75, 1.5)
  std::string s = "Pf\n2 2\n1.0\n";
  for (float v : vals) {
    uint32_t u;
    std::memcpy(&u, &v, 4);
    for (int b = 3; b >= 0; --b) s += char((u >> (8 * b)) & 0xff);
  }
  write_bytes(dir / "g.pfm", s);
  Image img = read_image(dir / "g.pfm");
  ASSERT_EQ(img.width, 2);
  EXPECT_EQ(img.at(0, 1).x, 0.25f);
  EXPECT_EQ(img.at(1, 1).y, 0.5f);
  EXPECT_EQ(img.at(0, 0).z, 0.75f);
  EXPECT_EQ(img.at(1, 0).x, 1.5f);
  // Truncated raster and bad headers.
  write_bytes(dir / "t.pfm", s.substr(0, s.size() - 1));
  expect_error([&] { read_image(dir / "t.pfm"); }, {"t.pfm", "truncated"});
  write_bytes(dir / "h.pfm", "PF\n2 x\n-1\n");
  expect_error([&] { read_image(dir / "h.pfm"); }, {"h.pfm", "height"});
  write_bytes(dir / "m.pfm", "P6\n2 2\n255\n");
  expect_error([&] { read_image(dir / "m.pfm"); }, {"m.pfm", "not a PFM"});
}

TEST(Image, FileErrors) {
  TmpDir dir;
  Image img(4, 4);
  expect_error([&] { write_image(dir / "a.jpg", img); }, {"a.jpg", "unknown image extension"});
  expect_error([&] { write_image(dir / "noext", img); }, {"noext", "unknown image extension"});
  expect_error([&] { read_image(dir / "a.tif"); }, {"unknown image extension"});
  expect_error([&] { read_image(dir / "missing.png"); }, {"missing.png", "cannot open"});
  expect_error([&] { write_image(dir / "e.png", Image()); }, {"empty"});
  expect_error([&] { write_image(dir / "nodir/x.png", img); }, {"cannot write"});
  write_bytes(dir / "text.png", "hello, not a png");
  expect_error([&] { read_image(dir / "text.png"); }, {"text.png", "not a PNG"});
  // A real PNG cut short.
  write_image(dir / "ok.png", random_image(16, 16, 3));
  const std::string bytes = read_file(dir / "ok.png");
  write_bytes(dir / "cut.png", bytes.substr(0, bytes.size() / 2));
  expect_error([&] { read_image(dir / "cut.png"); }, {"cut.png", "corrupt PNG"});
  // Corrupt IHDR (CRC mismatch).
  std::string bad = bytes;
  bad[17] ^= 0x55;
  write_bytes(dir / "crc.png", bad);
  expect_error([&] { read_image(dir / "crc.png"); }, {"crc.png", "corrupt PNG"});
}

// ---- metrics ------------------------------------------------------------------------------------

namespace {

// B.4 written out directly: every 7x7 window fully inside, two-pass mean, (n-1) covariance.
double ssim_brute(const Image& a, const Image& b) {
  double total = 0;
  int count = 0;
  for (int k = 0; k < 3; ++k)
    for (int y0 = 0; y0 + 7 <= a.height; ++y0)
      for (int x0 = 0; x0 + 7 <= a.width; ++x0) {
        auto ch = [&](const Image& im, int x, int y) {
          const Vec4f p = im.at(x, y);
          return double(std::clamp(k == 0 ? p.x : (k == 1 ? p.y : p.z), 0.0f, 1.0f));
        };
        double ma = 0, mb = 0;
        for (int y = y0; y < y0 + 7; ++y)
          for (int x = x0; x < x0 + 7; ++x) ma += ch(a, x, y), mb += ch(b, x, y);
        ma /= 49;
        mb /= 49;
        double va = 0, vb = 0, cov = 0;
        for (int y = y0; y < y0 + 7; ++y)
          for (int x = x0; x < x0 + 7; ++x) {
            const double da = ch(a, x, y) - ma, db = ch(b, x, y) - mb;
            va += da * da, vb += db * db, cov += da * db;
          }
        va /= 48, vb /= 48, cov /= 48;
        const double c1 = 1e-4, c2 = 9e-4;
        total += (2 * ma * mb + c1) * (2 * cov + c2) / ((ma * ma + mb * mb + c1) * (va + vb + c2));
        ++count;
      }
  return total / count;
}

}  // namespace

TEST(ImageMetrics, IdenticalAndKnownMse) {
  Image a = random_image(20, 12, 1);
  ImageMetrics same = compare_images(a, a);
  EXPECT_EQ(same.mse, 0);
  EXPECT_EQ(same.psnr, 999.0);
  EXPECT_NEAR(same.ssim, 1, 1e-9);
  // Alpha is ignored, values are clamped to [0,1] first.
  Image b = a;
  for (auto& p : b.pixels) p.w = 0.3f;
  b.at(3, 3) = Vec4f{std::max(a.at(3, 3).x, 1.0f) + 5, a.at(3, 3).y, a.at(3, 3).z, 0};
  a.at(3, 3).x = 1.0f;
  EXPECT_EQ(compare_images(b, a).mse, 0);
  // Constant 0.5 vs 0.75 (both exact in binary): mse 1/16, psnr 10 log10(16).
  Image c(9, 9), d(9, 9);
  for (auto& p : c.pixels) p = Vec4f{0.5f, 0.5f, 0.5f, 1};
  for (auto& p : d.pixels) p = Vec4f{0.75f, 0.75f, 0.75f, 1};
  ImageMetrics m = compare_images(c, d);
  EXPECT_DOUBLE_EQ(m.mse, 1.0 / 16);
  EXPECT_NEAR(m.psnr, 10 * std::log10(16.0), 1e-12);
  // Only one channel off by 0.3 in a quarter of the pixels: mse = 0.09 / 12.
  Image e(4, 4), f(4, 4);
  for (int i = 0; i < 4; ++i) f.pixels[i].y = 0.3f;
  EXPECT_NEAR(compare_images(e, f).mse, double(0.3f) * double(0.3f) / 12, 1e-12);
}

TEST(ImageMetrics, SsimHandComputed) {
  // 7x7: a single window per channel. Constant images: variances 0, SSIM = the luminance term.
  Image c(7, 7), d(7, 7);
  for (auto& p : c.pixels) p = Vec4f{0.5f, 0.5f, 0.5f, 1};
  for (auto& p : d.pixels) p = Vec4f{0.75f, 0.75f, 0.75f, 1};
  const double c1 = 1e-4;
  EXPECT_NEAR(compare_images(c, d).ssim, (2 * 0.5 * 0.75 + c1) / (0.25 + 0.5625 + c1), 1e-9);
  // A shifted copy keeps the structure term at 1; a contrast-doubled copy keeps the luminance at 1.
  Image g(7, 7), shifted(7, 7), contrast(7, 7);
  double m = 0, var = 0;
  for (int i = 0; i < 49; ++i) {
    const float v = 0.25f + 0.125f * float(i % 5) / 4;  // multiples of 1/32: exact
    g.pixels[i] = Vec4f{v, v, v, 1};
    m += v;
  }
  m /= 49;
  for (int i = 0; i < 49; ++i) {
    const float v = g.pixels[i].x;
    var += (v - m) * (v - m);
    shifted.pixels[i] = Vec4f{v + 0.25f, v + 0.25f, v + 0.25f, 1};
    const float cv = float(m + 2 * (v - m));
    contrast.pixels[i] = Vec4f{cv, cv, cv, 1};
  }
  var /= 48;
  const double c2 = 9e-4;
  EXPECT_NEAR(compare_images(shifted, g).ssim, (2 * m * (m + 0.25) + c1) / (m * m + (m + 0.25) * (m + 0.25) + c1), 1e-7);
  EXPECT_NEAR(compare_images(contrast, g).ssim, (2 * 2 * var + c2) / (var + 4 * var + c2), 1e-6);
}

TEST(ImageMetrics, SsimOfNoisyImageMatchesBruteForce) {
  Image a = random_image(19, 13, 7);
  Image b = a;
  Pcg32 rng(99);
  for (auto& p : b.pixels) {
    p.x += 0.1f * (rng.next_float() - 0.5f);
    p.y += 0.1f * (rng.next_float() - 0.5f);
    p.z += 0.1f * (rng.next_float() - 0.5f);
  }
  ImageMetrics m = compare_images(b, a);
  EXPECT_LT(m.ssim, 0.999);
  EXPECT_GT(m.ssim, 0.5);
  EXPECT_NEAR(m.ssim, ssim_brute(b, a), 1e-9);
  EXPECT_GT(m.psnr, 20);
  EXPECT_TRUE(std::isfinite(m.psnr));
}

TEST(ImageMetrics, SizeMismatchFails) {
  expect_error([] { compare_images(Image(4, 4), Image(4, 5)); }, {"size mismatch", "4x4", "4x5"});
  expect_error([] { compare_images(Image(), Image()); }, {"empty"});
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
