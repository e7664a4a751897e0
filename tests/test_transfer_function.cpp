// Transfer functions: presets, lookup, instantvnr's TF objects (base64 opacity arrays) and vnr's
// simple format, with their errors.
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

}  // namespace

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
