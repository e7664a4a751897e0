// Client -> server messages: each checked field by field (a clear error names the field), then turned
// into engine calls that start from the engine's current settings (messages are partial updates).
#include <array>
#include <cmath>
#include <optional>
#include "view/protocol.h"
#include "vnr/error.h"
#include "vnr/render_settings.h"

namespace vnr::view {

namespace {

// Reads the optional fields of one message, naming "type.field" in errors.
class Fields {
public:
  Fields(const Json& msg, std::string type) : msg_(msg), type_(std::move(type)) {}

  const Json* get(const char* name) const {
    auto it = msg_.find(name);
    return it == msg_.end() ? nullptr : &*it;
  }
  std::optional<double> number(const char* name, double lo, double hi) const {
    const Json* j = get(name);
    if (!j) return std::nullopt;
    if (!j->is_number()) fail("{}.{} must be a number, got {}", type_, name, short_dump(*j));
    const double v = j->get<double>();
    if (!std::isfinite(v) || v < lo || v > hi) fail("{}.{} = {} is outside [{}, {}]", type_, name, short_dump(*j), lo, hi);
    return v;
  }
  std::optional<int64_t> integer(const char* name, int64_t lo, int64_t hi) const {
    const Json* j = get(name);
    if (!j) return std::nullopt;
    if (!j->is_number() || (j->is_number_float() && std::floor(j->get<double>()) != j->get<double>()))
      fail("{}.{} must be an integer, got {}", type_, name, short_dump(*j));
    const double v = j->get<double>();
    if (!(v >= double(lo) && v <= double(hi))) fail("{}.{} = {} is outside [{}, {}]", type_, name, short_dump(*j), lo, hi);
    return int64_t(v);
  }
  std::optional<bool> boolean(const char* name) const {
    const Json* j = get(name);
    if (!j) return std::nullopt;
    if (!j->is_boolean()) fail("{}.{} must be true or false, got {}", type_, name, short_dump(*j));
    return j->get<bool>();
  }
  std::optional<std::string> string(const char* name) const {
    const Json* j = get(name);
    if (!j) return std::nullopt;
    if (!j->is_string()) fail("{}.{} must be a string, got {}", type_, name, short_dump(*j));
    return j->get<std::string>();
  }
  std::string required_string(const char* name) const {
    std::optional<std::string> s = string(name);
    if (!s) fail("{} needs the field \"{}\"", type_, name);
    return *s;
  }
  // One of `values`, by the name name_of gives it.
  template <class T, size_t N>
  std::optional<T> choice(const char* name, const std::array<T, N>& values, const char* (*name_of)(T)) const {
    std::optional<std::string> s = string(name);
    if (!s) return std::nullopt;
    std::string list;
    for (const T& v : values) {
      if (*s == name_of(v)) return v;
      list += (list.empty() ? "" : ", ") + std::string(name_of(v));
    }
    fail("{}.{} = \"{}\" is not one of {}", type_, name, *s, list);
  }
  // An array of exactly `n` finite numbers.
  std::vector<float> numbers(const Json& j, size_t n, const std::string& what) const {
    if (!j.is_array() || j.size() != n) fail("{} must be an array of {} numbers, got {}", what, n, short_dump(j));
    std::vector<float> v;
    for (const Json& e : j) {
      if (!e.is_number() || !std::isfinite(e.get<double>())) fail("{} must hold finite numbers, got {}", what, short_dump(j));
      v.push_back(e.get<float>());
    }
    return v;
  }
  std::optional<Vec3f> vec3(const char* name) const {
    const Json* j = get(name);
    if (!j) return std::nullopt;
    std::vector<float> v = numbers(*j, 3, type_ + "." + name);
    return Vec3f{v[0], v[1], v[2]};
  }
  // An array of rows of `n` numbers each, at most max_rows.
  std::optional<std::vector<std::vector<float>>> rows(const char* name, size_t n, size_t max_rows) const {
    const Json* j = get(name);
    if (!j) return std::nullopt;
    const std::string what = type_ + "." + name;
    if (!j->is_array()) fail("{} must be an array of [{} numbers] rows, got {}", what, n, short_dump(*j));
    if (j->size() > max_rows) fail("{} has {} entries, at most {} allowed", what, j->size(), max_rows);
    std::vector<std::vector<float>> out;
    for (size_t i = 0; i < j->size(); ++i) out.push_back(numbers((*j)[i], n, what + "[" + std::to_string(i) + "]"));
    return out;
  }
  static std::string short_dump(const Json& j) {
    std::string s = json_text(j);
    return s.size() > 80 ? s.substr(0, 77) + "..." : s;
  }

private:
  const Json& msg_;
  std::string type_;
};

using Run = std::function<Json(ViewerEngine&)>;

Run camera_command(const Fields& f) {
  auto eye = f.vec3("eye"), center = f.vec3("center"), up = f.vec3("up");
  auto fovy = f.number("fovy", 1, 179);
  const bool interacting = f.boolean("interacting").value_or(false);
  return [=](ViewerEngine& e) {
    Camera c = e.state().camera;
    if (eye) c.eye = *eye;
    if (center) c.center = *center;
    if (up) c.up = *up;
    if (fovy) c.fovy = float(*fovy);
    const Vec3f d = c.center - c.eye;
    if (d.x == 0 && d.y == 0 && d.z == 0) fail("camera: eye and center are the same point");
    if (c.up.x == 0 && c.up.y == 0 && c.up.z == 0) fail("camera: up is the zero vector");
    e.set_camera(c, interacting);
    return Json();
  };
}

Run viewport_command(const Fields& f) {
  auto w = f.integer("width", 16, 4096), h = f.integer("height", 16, 4096);
  return [=](ViewerEngine& e) {
    const ViewerState s = e.state();
    e.set_viewport(int(w.value_or(s.width)), int(h.value_or(s.height)));
    return Json();
  };
}

Run view_command(const Fields& f) {
  auto layout = f.choice("layout", std::array{ViewLayout::Network, ViewLayout::Truth, ViewLayout::SideBySide,
                                               ViewLayout::Split}, view_layout_name);
  auto split = f.number("split", 0, 1), position = f.number("slice_position", 0, 1);
  auto slice = f.boolean("slice");
  auto axis = f.integer("slice_axis", 0, 2);
  return [=](ViewerEngine& e) {
    ViewSettings v = e.state().view;
    if (layout) v.layout = *layout;
    if (split) v.split = float(*split);
    if (slice) v.slice = *slice;
    if (axis) v.slice_axis = int(*axis);
    if (position) v.slice_position = float(*position);
    e.set_view(v);
    return Json();
  };
}

Run tf_command(const Fields& f) {
  auto colormap = f.string("colormap");
  auto colors = f.rows("custom_colors", 3, 4096), opacity = f.rows("opacity", 2, 4096);
  std::optional<std::vector<float>> range;
  if (const Json* r = f.get("range")) range = f.numbers(*r, 2, "tf.range");
  return [=](ViewerEngine& e) {
    ViewerTf tf = e.state().tf;
    if (colormap) tf.colormap = *colormap;
    if (colors) {
      tf.custom_colors.clear();
      for (const auto& c : *colors) tf.custom_colors.push_back(Vec3f{c[0], c[1], c[2]});
    }
    if (opacity) {
      tf.opacity.clear();
      for (const auto& p : *opacity) tf.opacity.push_back({p[0], p[1]});
    }
    if (range) {
      tf.lo = (*range)[0];
      tf.hi = (*range)[1];
    }
    e.set_tf(tf);
    return Json();
  };
}

// The render settings the page changes, by RenderSettings' keys and values (the image size, camera and
// transfer function have messages of their own), checked by RenderSettings::validate at once, so the
// allowed values are the library's; and the viewer's own max_frames and coarse_scale.
Run render_command(const Fields& f) {
  auto mode = f.string("mode"), strategy = f.string("strategy"), macrocells = f.string("macrocells");
  RenderSettings given;  // the given values over the defaults
  if (mode) given.mode = *mode;
  if (strategy) given.strategy = *strategy;
  if (macrocells) given.macrocells = *macrocells;
  given.validate([](const std::string& key) { return "render." + key; });
  auto step = f.number("step", 1e-3, 1e3), density = f.number("density", 0, 1e6);
  auto shade = f.boolean("shade");
  auto light = f.vec3("light");
  auto max_frames = f.integer("max_frames", 0, 1 << 20), coarse = f.integer("coarse_scale", 1, 64);
  return [=](ViewerEngine& e) {
    ViewerRender r = e.state().render;  // the library's RenderSettings, and the viewer's own two
    if (mode) r.settings.mode = *mode;
    if (strategy) r.settings.strategy = *strategy;
    if (macrocells) r.settings.macrocells = *macrocells;
    if (step) r.settings.step = float(*step);
    if (shade) r.settings.shade = *shade;
    if (light) r.settings.light = *light;
    if (density) r.settings.density = float(*density);
    if (max_frames) r.max_frames = int(*max_frames);
    if (coarse) r.coarse_scale = int(*coarse);
    e.set_render(r);
    return Json();
  };
}

enum class TrainAction { Start, Pause, Reset };
const char* train_action_name(TrainAction a) { return std::array{"start", "pause", "reset"}[size_t(a)]; }

Run train_command(const Fields& f) {
  auto action = f.choice("action", std::array{TrainAction::Start, TrainAction::Pause, TrainAction::Reset},
                         train_action_name);
  auto lr = f.number("learning_rate", 1e-12, 1e3);
  auto budget = f.number("budget", 0, 10);
  if (lr && action != TrainAction::Reset) fail("train.learning_rate goes with action \"reset\" only");
  if (!action && !budget) fail("train needs \"action\" (start, pause, reset) or \"budget\"");
  return [=](ViewerEngine& e) {
    if (budget) e.set_training_budget(*budget);
    if (action == TrainAction::Start) e.start_training();
    if (action == TrainAction::Pause) e.pause_training();
    if (action == TrainAction::Reset) e.reset_training(lr);
    return Json();
  };
}

Run timestep_command(const Fields& f) {
  auto index = f.integer("index", 0, int64_t(1) << 30);
  auto continuous = f.boolean("continuous");
  auto every = f.integer("switch_every", 1, int64_t(1) << 40);
  if (!index && !continuous && !every) fail("timestep needs \"index\", \"continuous\" or \"switch_every\"");
  return [=](ViewerEngine& e) {
    if (index) e.set_timestep(int(*index));
    if (continuous || every) {
      const ViewerTraining t = e.state().training;
      e.set_continuous(continuous.value_or(t.continuous), every.value_or(t.switch_every));
    }
    return Json();
  };
}

}  // namespace

ClientCommand parse_client_message(std::string_view text) {
  Json msg;
  try {
    msg = Json::parse(text);
  } catch (const Json::exception& ex) {
    fail("malformed JSON message: {}", ex.what());
  }
  if (!msg.is_object()) fail("a message must be a JSON object with a \"type\"");
  auto t = msg.find("type");
  if (t == msg.end() || !t->is_string()) fail("a message needs a string \"type\"");
  const std::string type = t->get<std::string>();
  const Fields f(msg, type);
  ClientCommand c{type, false, {}};
  if (type == "camera") c.run = camera_command(f);
  else if (type == "reset_camera") c.run = [](ViewerEngine& e) { e.reset_camera(); return Json(); };
  else if (type == "viewport") c.run = viewport_command(f);
  else if (type == "cursor") {
    auto x = f.number("x", 0, 1), y = f.number("y", 0, 1);
    if (bool(x) != bool(y)) fail("cursor.x and cursor.y go together (neither: no cursor)");
    c.run = [=](ViewerEngine& e) {
      e.set_cursor(x ? std::optional<std::array<float, 2>>({float(*x), float(*y)}) : std::nullopt);
      return Json();
    };
  }
  else if (type == "view") c.run = view_command(f);
  else if (type == "tf") c.run = tf_command(f);
  else if (type == "tf_load") {
    const std::string text_field = f.required_string("text");
    c.run = [text_field](ViewerEngine& e) { e.load_tf_json(text_field); return Json(); };
  } else if (type == "render") c.run = render_command(f);
  else if (type == "train") c.run = train_command(f);
  else if (type == "timestep") c.run = timestep_command(f);
  else if (type == "save") {
    const std::string name = f.required_string("name");
    c.slow = true;
    c.run = [name](ViewerEngine& e) { return Json{{"type", "saved"}, {"path", e.save_model(name)}}; };
  } else if (type == "ping") {
    const Json* id = f.get("id");
    const Json echo = id ? *id : Json();
    c.run = [echo](ViewerEngine&) { return Json{{"type", "pong"}, {"id", echo}}; };
  } else {
    fail("unknown message type {}", Fields::short_dump(Json(type)));
  }
  return c;
}

std::string run_command(const ClientCommand& command, ViewerEngine& engine) {
  try {
    const Json reply = command.run(engine);
    return reply.is_null() ? std::string() : json_text(reply);
  } catch (const std::exception& e) {  // vnr::Error and whatever else the engine throws
    return error_message(command.type + ": " + e.what());
  }
}

}  // namespace vnr::view
