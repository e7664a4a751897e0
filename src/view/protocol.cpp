// Server -> client messages: ViewerInfo / ViewerState / frames as the JSON docs/VIEWER.md names.
#include "view/protocol.h"
#include "vnr/dtype.h"
#include "vnr/error.h"

namespace vnr::view {

namespace {

Json vec3(Vec3f v) { return Json::array({v.x, v.y, v.z}); }

const char* training_state_name(TrainingState s) {
  switch (s) {
    case TrainingState::Unavailable: return "unavailable";
    case TrainingState::Idle: return "idle";
    case TrainingState::Running: return "running";
    case TrainingState::Paused: return "paused";
  }
  return "unavailable";
}

Json tf_json(const ViewerTf& tf) {
  Json colors = Json::array(), opacity = Json::array();
  for (const Vec3f& c : tf.custom_colors) colors.push_back(vec3(c));
  for (const auto& p : tf.opacity) opacity.push_back({p[0], p[1]});
  return {{"colormap", tf.colormap}, {"custom_colors", colors}, {"opacity", opacity}, {"range", {tf.lo, tf.hi}}};
}

Json render_json(const ViewerRender& r) {
  const RenderSettings& s = r.settings;
  return {{"mode", s.mode},
          {"strategy", s.strategy},
          {"macrocells", s.macrocells},
          {"step", s.step},
          {"shade", s.shade},
          {"light", vec3(s.light.value_or(viewer_default_light()))},
          {"density", s.density},
          {"max_frames", r.max_frames},
          {"coarse_scale", r.coarse_scale}};
}

Json training_json(const ViewerTraining& t) {
  return {{"state", training_state_name(t.state)},
          {"step", t.step},
          {"loss", t.loss},
          {"samples_per_second", t.samples_per_second},
          {"seconds", t.seconds},
          {"psnr", t.psnr},
          {"learning_rate", t.learning_rate},
          {"budget", t.budget_seconds},
          {"timestep", t.timestep},
          {"continuous", t.continuous},
          {"switch_every", t.switch_every},
          {"n_losses", t.n_losses}};
}

}  // namespace

const char* view_layout_name(ViewLayout l) {
  switch (l) {
    case ViewLayout::Network: return "network";
    case ViewLayout::Truth: return "truth";
    case ViewLayout::SideBySide: return "side_by_side";
    case ViewLayout::Split: return "split";
  }
  return "network";
}

Json info_json(const ViewerInfo& i) {
  return {{"description", i.description},
          {"dims", {i.dims.x, i.dims.y, i.dims.z}},
          {"source_dtype", dtype_name(i.source_dtype)},
          {"lo", i.lo},
          {"hi", i.hi},
          {"has_volume", i.has_volume},
          {"has_model", i.has_model},
          {"can_train", i.can_train},
          {"n_timesteps", i.n_timesteps},
          {"device", i.device},
          {"config", i.config},
          {"n_params", i.n_params},
          {"colormaps", i.colormaps},
          {"save_dir", i.save_dir}};
}

Json state_json(const ViewerState& s) {
  const ViewSettings& v = s.view;
  return {{"version", s.version},
          {"camera", {{"eye", vec3(s.camera.eye)}, {"center", vec3(s.camera.center)}, {"up", vec3(s.camera.up)},
                      {"fovy", s.camera.fovy}}},
          {"viewport", {{"width", s.width}, {"height", s.height}}},
          {"view", {{"layout", view_layout_name(v.layout)}, {"split", v.split}, {"slice", v.slice},
                    {"slice_axis", v.slice_axis}, {"slice_position", v.slice_position}}},
          {"tf", tf_json(s.tf)},
          {"render", render_json(s.render)},
          {"training", training_json(s.training)},
          {"error_count", s.error_count},
          {"last_error", s.last_error}};
}

std::string json_text(const Json& j) { return j.dump(-1, ' ', false, Json::error_handler_t::replace); }

std::string hello_message(const ViewerInfo& info, const std::vector<uint32_t>& histogram, const ViewerState& state) {
  return json_text({{"type", "hello"}, {"info", info_json(info)}, {"histogram", histogram}, {"state", state_json(state)}});
}

std::string state_message(const ViewerState& state) { return json_text({{"type", "state"}, {"state", state_json(state)}}); }

std::string losses_message(size_t from, const float* values, size_t n, const std::vector<std::array<double, 2>>& psnr) {
  Json v = Json::array(), p = Json::array();
  for (size_t i = 0; i < n; ++i) v.push_back(values[i]);
  for (const auto& e : psnr) p.push_back({e[0], e[1]});
  return json_text({{"type", "losses"}, {"from", from}, {"values", v}, {"psnr", p}});
}

std::string error_message(std::string_view message) {
  return json_text({{"type", "error"}, {"message", std::string(message)}});
}

std::string frame_message_head(const ViewerFrame& f, const ViewerImage& im) {
  const std::string header = json_text({{"frame", f.id},
                                   {"view", im.view},
                                   {"version", f.state_version},
                                   {"width", im.width},
                                   {"height", im.height},
                                   {"refined", f.refined},
                                   {"accumulated", f.accumulated},
                                   {"render_ms", f.render_seconds * 1e3},
                                   {"train_ms", f.train_seconds * 1e3},
                                   {"step", f.step},
                                   {"cache", f.cache_bricks < 0 ? Json(nullptr)
                                                                : Json{{"bricks", f.cache_bricks},
                                                                       {"stale", f.cache_stale},
                                                                       {"pending", f.cache_pending}}}});
  const uint32_t n = uint32_t(header.size());
  std::string out(4, '\0');
  for (int k = 0; k < 4; ++k) out[size_t(k)] = char((n >> (8 * k)) & 255);  // little-endian on any host
  return out + header;
}

FrameMessageParts split_frame_message(std::string_view m) {
  if (m.size() < 4) fail("binary frame message of {} bytes has no header length", m.size());
  uint32_t n = 0;
  for (int k = 0; k < 4; ++k) n |= uint32_t(static_cast<unsigned char>(m[size_t(k)])) << (8 * k);
  if (n > m.size() - 4) fail("binary frame message: header length {} exceeds the message", n);
  return {parse_json_text(std::string(m.substr(4, n)), "frame header"), m.substr(4 + n)};
}

}  // namespace vnr::view
