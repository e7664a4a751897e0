// vnr::RenderSettings (include/vnr/render_settings.h): JSON in and out with its defaults and refusals,
// and setup_renderer against a Renderer set up call by call.
#include <gtest/gtest.h>
#include <cstring>
#include "render_support.h"
#include "test_support.h"
#include "vnr/vnr.h"

using namespace vnr;
using namespace vnr::test;

namespace {

std::string error_of_settings(const Json& j) {
  try {
    RenderSettings::from_json(j);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

bool same_pixels(const Image& a, const Image& b) {
  return a.width == b.width && a.height == b.height &&
         std::memcmp(a.pixels.data(), b.pixels.data(), a.pixels.size() * sizeof(Vec4f)) == 0;
}

}  // namespace

TEST(RenderSettings, JsonRoundTripsAndDefaultsAreTheStructs) {
  const RenderSettings d;
  EXPECT_EQ(RenderSettings::from_json(Json::object()).to_json(), d.to_json());
  EXPECT_EQ(RenderSettings::from_json(d.to_json()).to_json(), d.to_json());

  const Json j = {{"mode", "pathtrace"},  {"strategy", "streaming"}, {"size", {320, 200}},
                  {"step", 0.5},          {"step_max", 4},            {"density", 2},
                  {"shade", true},        {"seed", 9},                {"samples_per_iteration", 4},
                  {"ray_packets", false}, {"light", {1, 2, 3}},       {"background", {0.1, 0.2, 0.3}},
                  {"tf", "cool-warm"},    {"macrocells", "grid"},     {"macrocell_size", 8},
                  {"eye", {1, 2, 40}},    {"center", {1, 2, 3}},      {"up", {0, 0, 1}},
                  {"fovy", 45},           {"orbit", {30, -10}},       {"device", "cpu"},
                  {"mlp", "fused"},       {"precision", "fp32"},      {"cache_budget", "64MiB"},
                  {"cache_dims", {64, 64, 32}}, {"spp", 3},           {"noise", 0.01},
                  {"max_spp", 64}};
  const RenderSettings s = RenderSettings::from_json(j);
  EXPECT_EQ(s.mode, "pathtrace");
  EXPECT_EQ(s.width, 320);
  EXPECT_EQ(s.height, 200);
  EXPECT_EQ(s.cache_budget, uint64_t(64) << 20);
  EXPECT_TRUE(s.cache_dims == (Int3{64, 64, 32}));
  ASSERT_TRUE(s.orbit.has_value());
  EXPECT_EQ(s.orbit->second, -10.0f);
  EXPECT_FALSE(s.ray_packets);
  // Written and read again: the same settings (the budget now in bytes).
  EXPECT_EQ(RenderSettings::from_json(s.to_json()).to_json(), s.to_json());
  EXPECT_EQ(s.to_json()["cache_budget"], uint64_t(64) << 20);
  // An orbit of one number is an azimuth.
  EXPECT_EQ(RenderSettings::from_json(Json{{"orbit", {25}}}).orbit->second, 0.0f);
}

TEST(RenderSettings, RefusesUnknownKeysAndBadValuesNamingThem) {
  std::string msg = error_of_settings(Json{{"zoom", 2}});
  EXPECT_NE(msg.find("unknown key 'zoom'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("allowed: "), std::string::npos) << msg;
  EXPECT_NE(msg.find("orbit"), std::string::npos) << msg;
  const std::vector<std::pair<Json, std::string>> cases = {
      {Json::array(), "must be a JSON object"},
      {{{"mode", "xray"}}, "render mode 'xray'"},
      {{{"strategy", "fast"}}, "render strategy 'fast'"},
      {{{"size", {0, 10}}}, "size: the image must be positive"},
      {{{"size", "512x512"}}, "'size' must be [width, height]"},
      {{{"step", 0}}, "step must be"},
      {{{"eye", {1, 2, 3}}}, "eye and center go together"},
      {{{"light", {1, 2}}}, "'light' must be [x, y, z]"},
      {{{"fovy", 180}}, "fovy"},
      {{{"device", "tpu"}}, "device 'tpu'"},
      {{{"mlp", "tiny"}}, "MLP path 'tiny'"},
      {{{"precision", "fp8"}}, "precision 'fp8'"},
      {{{"macrocells", "some"}}, "some"},
      {{{"macrocell_size", 0}}, "macrocell_size"},
      {{{"cache_dims", {0, 4, 4}}}, "cache_dims must be positive"},
      {{{"cache_budget", "lots"}}, "lots"},
      {{{"max_spp", 2}}, "max_spp must be at least 4"},
      {{{"noise", -1}}, "noise must be at least 0"},
      {{{"shade", 1}}, "'shade' must be true or false"},
  };
  for (const auto& [j, needle] : cases) {
    msg = error_of_settings(j);
    EXPECT_NE(msg.find(needle), std::string::npos) << j.dump() << " -> " << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  }
}

// setup_renderer gives the image of a Renderer whose settings were made call by call.
TEST(RenderSettings, SetupRendererEqualsARendererSetByHand) {
  GridScene g;
  RenderSettings s;
  s.width = 40;
  s.height = 32;
  s.orbit = std::make_pair(30.0f, 20.0f);
  s.tf = "cool-warm";
  s.macrocells = "grid";
  s.macrocell_size = 8;
  s.strategy = "streaming";
  s.seed = 3;
  s.shade = true;
  s.background = Vec3f{0.2f, 0.3f, 0.4f};
  s.device = "cpu";
  s.spp = 2;
  RenderSetup setup = setup_renderer(nullptr, &g.vol, Scene{}, s);
  EXPECT_EQ(setup.orbit_elevation, 20.0f);
  EXPECT_TRUE(setup.notes.empty());
  Renderer& r = *setup.renderer;
  r.render_frame();
  r.render_frame();

  Renderer hand(g.vol, Device::Cpu);
  RenderOptions o;
  o.width = 40;
  o.height = 32;
  o.seed = 3;
  o.shade = true;
  o.background = Vec3f{0.2f, 0.3f, 0.4f};
  hand.set_options(o);
  hand.set_camera(orbit_camera(box_of(g.vol), 30, 20, 30));
  hand.set_transfer_function(tf_preset("cool-warm"));
  hand.set_macrocells(MacroCellMode::Grid, 8);
  hand.set_strategy(RenderStrategy::Streaming);
  hand.render_frame();
  hand.render_frame();
  EXPECT_TRUE(same_pixels(r.image(), hand.image()));

  // The transfer function as JSON text is the same table as the preset.
  const TransferFunction preset = tf_preset("cool-warm");
  const TransferFunction from_text = transfer_function_of(tf_to_instantvnr_json(preset).dump());
  ASSERT_EQ(from_text.table.size(), preset.table.size());
  for (size_t i = 0; i < preset.table.size(); ++i) EXPECT_NEAR(from_text.table[i].w, preset.table[i].w, 1e-6f);

  // A volume has no cache to size; settings that fail validation fail here too.
  s.cache_dims = Int3{8, 8, 8};
  EXPECT_THROW(setup_renderer(nullptr, &g.vol, Scene{}, s), Error);
  s.cache_dims = Int3{0, 0, 0};
  s.eye = Vec3f{1, 2, 3};
  EXPECT_THROW(setup_renderer(nullptr, &g.vol, Scene{}, s), Error);
}
