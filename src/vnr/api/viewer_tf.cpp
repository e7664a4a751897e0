// The transfer-function editor's model (ViewerTf) and its files: ViewerTf <-> the renderer's table,
// the current TF / scene as instantvnr files, and loading any TF or scene text.
#include <algorithm>
#include <cmath>
#include "vnr/api/viewer_impl.h"
#include "vnr/error.h"
#include "vnr/json.h"

namespace vnr {

namespace {

constexpr int kTableSize = 1024;  // the presets' resolution
constexpr size_t kMaxOpacityPoints = 64;
constexpr float kSimplifyTolerance = 1e-3f;
constexpr float kPresetMatchTolerance = 1e-5f;

// Piecewise-linear through points (x sorted), constant beyond the ends.
float eval_points(const std::vector<std::array<float, 2>>& p, float x) {
  if (x <= p.front()[0]) return p.front()[1];
  if (x >= p.back()[0]) return p.back()[1];
  auto hi = std::upper_bound(p.begin(), p.end(), x, [](float v, const std::array<float, 2>& q) { return v < q[0]; });
  auto lo = hi - 1;
  const float w = (*hi)[0] - (*lo)[0];
  const float t = w > 0 ? (x - (*lo)[0]) / w : 1.0f;
  return (*lo)[1] + ((*hi)[1] - (*lo)[1]) * t;
}

// The alpha table as at most kMaxOpacityPoints points that reproduce it within kSimplifyTolerance
// (greedy: add the entry of largest error until it fits), or every entry when that is not possible.
std::vector<std::array<float, 2>> simplify_alpha(const std::vector<Vec4f>& table) {
  const size_t n = table.size();
  auto x_of = [&](size_t i) { return float(double(i) / double(n - 1)); };
  std::vector<size_t> keep = {0, n - 1};
  for (;;) {
    std::vector<std::array<float, 2>> pts;
    for (size_t i : keep) pts.push_back({x_of(i), table[i].w});
    float worst = 0;
    size_t worst_i = 0;
    for (size_t i = 0; i < n; ++i) {
      const float e = std::fabs(eval_points(pts, x_of(i)) - table[i].w);
      if (e > worst) worst = e, worst_i = i;
    }
    if (worst <= kSimplifyTolerance) return pts;
    if (keep.size() >= kMaxOpacityPoints) break;
    keep.insert(std::upper_bound(keep.begin(), keep.end(), worst_i), worst_i);
  }
  std::vector<std::array<float, 2>> all;
  for (size_t i = 0; i < n; ++i) all.push_back({x_of(i), table[i].w});
  return all;
}

// The preset whose colours the table's equal (evaluated at the table's nodes), or "".
std::string matching_preset(const std::vector<Vec4f>& table) {
  const size_t n = table.size();
  for (const std::string& name : tf_preset_names()) {
    const TransferFunction p = tf_preset(name);
    const TfView v = view_of(p);
    bool same = true;
    for (size_t i = 0; i < n && same; ++i) {
      const Vec4f c = tf_lookup(v, float(double(i) / double(n - 1)));
      same = std::fabs(c.x - table[i].x) <= kPresetMatchTolerance && std::fabs(c.y - table[i].y) <= kPresetMatchTolerance &&
             std::fabs(c.z - table[i].z) <= kPresetMatchTolerance;
    }
    if (same) return name;
  }
  return "";
}

// The table's colours as few evenly spaced colours as reproduce them within kSimplifyTolerance (or all).
std::vector<Vec3f> even_colors(const std::vector<Vec4f>& table) {
  const size_t n = table.size();
  TransferFunction probe;
  probe.table = table;
  const TfView v = view_of(probe);
  for (size_t k : {2, 3, 5, 9, 17, 33, 65, 129, 257}) {
    if (k >= n) break;
    std::vector<Vec3f> c(k);
    for (size_t j = 0; j < k; ++j) {
      const Vec4f e = tf_lookup(v, float(double(j) / double(k - 1)));
      c[j] = Vec3f{e.x, e.y, e.z};
    }
    bool fits = true;
    for (size_t i = 0; i < n && fits; ++i) {
      const double x = double(i) / double(n - 1) * double(k - 1);
      const size_t j = std::min(size_t(x), k - 2);
      const float t = float(x - double(j));
      const Vec3f e = c[j] + t * (c[j + 1] - c[j]);
      fits = std::fabs(e.x - table[i].x) <= kSimplifyTolerance && std::fabs(e.y - table[i].y) <= kSimplifyTolerance &&
             std::fabs(e.z - table[i].z) <= kSimplifyTolerance;
    }
    if (fits) return c;
  }
  std::vector<Vec3f> all;
  for (const Vec4f& e : table) all.push_back(Vec3f{e.x, e.y, e.z});
  return all;
}

bool same_table(const std::vector<Vec4f>& a, const std::vector<Vec4f>& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i)
    if (a[i].x != b[i].x || a[i].y != b[i].y || a[i].z != b[i].z || a[i].w != b[i].w) return false;
  return true;
}

bool unit(float v) { return std::isfinite(v) && v >= 0 && v <= 1; }

}  // namespace

void check_viewer_tf(const ViewerTf& tf) {
  if (tf.colormap == "custom") {
    if (tf.custom_colors.size() < 2 || tf.custom_colors.size() > 4096)
      fail("custom colormap has {} colours; it needs 2..4096", tf.custom_colors.size());
    for (size_t i = 0; i < tf.custom_colors.size(); ++i) {
      const Vec3f c = tf.custom_colors[i];
      if (!unit(c.x) || !unit(c.y) || !unit(c.z))
        fail("custom colour {} ({}, {}, {}) is outside [0, 1]", i, c.x, c.y, c.z);
    }
  } else if (!is_tf_preset(tf.colormap)) {
    std::string list;
    for (const auto& p : tf_preset_names()) list += p + ", ";
    fail("colormap '{}' is neither a preset ({}) nor custom", tf.colormap, list + "custom");
  }
  if (tf.opacity.empty() || tf.opacity.size() > 4096)
    fail("the opacity has {} points; it needs 1..4096", tf.opacity.size());
  for (size_t i = 0; i < tf.opacity.size(); ++i) {
    const auto& p = tf.opacity[i];
    if (!unit(p[0]) || !unit(p[1])) fail("opacity point {} ({}, {}) is outside [0, 1]", i, p[0], p[1]);
    if (i > 0 && p[0] < tf.opacity[i - 1][0])
      fail("opacity point {} (x = {}) is left of the one before (x = {}): points must be sorted", i, p[0],
           tf.opacity[i - 1][0]);
  }
  if (!unit(tf.lo) || !unit(tf.hi) || !(tf.lo < tf.hi))
    fail("TF range [{}, {}] must satisfy 0 <= lo < hi <= 1", tf.lo, tf.hi);
}

// Colours: a preset's table at its nodes (so a preset with its own opacity points gives the preset's
// table), or the custom colours evenly spaced; opacity: the points, linear between.
TransferFunction to_transfer_function(const ViewerTf& tf) {
  check_viewer_tf(tf);
  std::vector<TfColorPoint> colors;
  if (tf.colormap == "custom") {
    const size_t k = tf.custom_colors.size();
    for (size_t j = 0; j < k; ++j) colors.push_back({double(j) / double(k - 1), tf.custom_colors[j]});
  } else {
    const TransferFunction p = tf_preset(tf.colormap);
    const size_t n = p.table.size();
    for (size_t i = 0; i < n; ++i) {
      const Vec4f& e = p.table[i];
      colors.push_back({double(i) / double(n - 1), Vec3f{e.x, e.y, e.z}});
    }
  }
  std::vector<TfAlphaPoint> alphas;
  for (const auto& p : tf.opacity) alphas.push_back({double(p[0]), p[1]});
  return tf_from_points(std::move(colors), std::move(alphas), kTableSize, tf.lo, tf.hi,
                        tf.colormap == "custom" ? "viewer" : tf.colormap);
}

ViewerTf viewer_tf_from_table(const TransferFunction& table) {
  if (table.table.size() < 2) fail("the transfer function needs at least 2 entries");
  ViewerTf tf;
  tf.lo = table.lo;
  tf.hi = table.hi;
  const std::string preset = matching_preset(table.table);
  if (!preset.empty() && table.lo == 0 && table.hi == 1 && same_table(table.table, tf_preset(preset).table)) {
    // A preset table: its own control points (to_transfer_function then gives the same table).
    tf.colormap = preset;
    for (const TfAlphaPoint& p : tf_preset_opacity(preset)) tf.opacity.push_back({float(p.x), p.a});
    return tf;
  }
  if (!preset.empty()) {
    tf.colormap = preset;
  } else {
    tf.colormap = "custom";
    tf.custom_colors = even_colors(table.table);
  }
  tf.opacity = simplify_alpha(table.table);
  return tf;
}

std::string ViewerEngine::tf_json() const {
  return tf_to_instantvnr_json(to_transfer_function(state().tf)).dump(2);
}

std::string ViewerEngine::scene_json() const {
  const ViewerState st = state();
  return scene_to_instantvnr_json(st.camera, to_transfer_function(st.tf)).dump(2);
}

void ViewerEngine::load_tf_json(const std::string& text) {
  if (text.size() > (size_t(1) << 24)) fail("the transfer function text is larger than 16 MiB");
  const Json j = parse_json_text(text, "the transfer function");
  if (!j.is_object()) fail("the transfer function must be a JSON object, got {}", j.type_name());
  const bool instantvnr_scene = is_instantvnr_scene(j);
  const bool vnr_scene = !instantvnr_scene && (j.contains("camera") || j.contains("transfer_function"));
  if (vnr_scene) {
    if (auto t = j.find("transfer_function"); t != j.end() && t->is_string() && !is_tf_preset(t->get<std::string>()))
      fail("the scene's transfer_function '{}' names a file; here only a preset or an inline object is accepted",
           t->get<std::string>());
  }
  std::optional<Camera> camera;
  std::optional<TransferFunction> table;
  if (instantvnr_scene || vnr_scene) {
    const Scene scene = scene_from_json(j, "the scene");
    camera = scene.camera;
    table = scene.tf;
    if (!camera && !table) fail("the scene has neither a camera nor a transfer function");
  } else {
    table = tf_from_json(j, "the transfer function");
  }
  std::optional<ViewerTf> tf;
  if (table) tf = viewer_tf_from_table(*table);
  // Both validated before anything changes.
  if (tf) check_viewer_tf(*tf);
  if (camera) set_camera(*camera, false);
  if (tf) set_tf(*tf);
}

}  // namespace vnr
