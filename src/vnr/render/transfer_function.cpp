// Transfer functions: presets, instantvnr's TF JSON (the instantvnr TF format) and vnr's simple
// control-point format.
//
// vnr's simple format: {"colors": [[v, r, g, b], ...], "opacities": [[v, a], ...], "resolution": N,
// "range": [lo, hi]}. Control positions v are in the table's own [0,1] coordinate (0 = lo, 1 = hi);
// colours and opacities are in [0,1]; points may come in any order (sorted by v, ties keep file
// order); the table entry i is the piecewise-linear function evaluated at i/(N-1) with constant
// extension beyond the first and last point, exactly like VTK's piecewise functions. Defaults:
// N = 1024, range [0,1]. Unknown keys are errors (typo safety).
#include "vnr/render/transfer_function.h"
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <fmt/format.h>
#include "vnr/error.h"
#include "vnr/fileio.h"

namespace vnr {

namespace {

constexpr int kMaxResolution = 65536;
constexpr int kDefaultResolution = 1024;

// ---- control points ------------------------------------------------------------------------------

using ColorPoint = TfColorPoint;
using AlphaPoint = TfAlphaPoint;

inline Vec3f lerp_value(Vec3f a, Vec3f b, double t) {
  const float tf = float(t);
  return Vec3f{a.x + (b.x - a.x) * tf, a.y + (b.y - a.y) * tf, a.z + (b.z - a.z) * tf};
}
inline float lerp_value(float a, float b, double t) { return float(double(a) + (double(b) - double(a)) * t); }

// Piecewise-linear with constant extension. `pts` sorted by x (stable), non-empty.
template <typename P, typename V, typename Get>
V eval_pwl(const std::vector<P>& pts, double x, Get get) {
  if (x <= pts.front().x) return get(pts.front());
  if (x >= pts.back().x) return get(pts.back());
  // First point strictly right of x; its predecessor is at or left of x.
  auto hi = std::upper_bound(pts.begin(), pts.end(), x, [](double v, const P& p) { return v < p.x; });
  auto lo = hi - 1;
  const double w = hi->x - lo->x;
  const double t = w > 0 ? (x - lo->x) / w : 1.0;
  return lerp_value(get(*lo), get(*hi), t);
}

Vec3f eval_color(const std::vector<ColorPoint>& pts, double x) {
  if (pts.empty()) return Vec3f{0, 0, 0};
  return eval_pwl<ColorPoint, Vec3f>(pts, x, [](const ColorPoint& p) { return p.c; });
}
float eval_alpha(const std::vector<AlphaPoint>& pts, double x) {
  if (pts.empty()) return 0.0f;
  return eval_pwl<AlphaPoint, float>(pts, x, [](const AlphaPoint& p) { return p.a; });
}

void sort_points(std::vector<ColorPoint>& c, std::vector<AlphaPoint>& a) {
  std::stable_sort(c.begin(), c.end(), [](const ColorPoint& p, const ColorPoint& q) { return p.x < q.x; });
  std::stable_sort(a.begin(), a.end(), [](const AlphaPoint& p, const AlphaPoint& q) { return p.x < q.x; });
}

// Node-centred table: entry i is both functions evaluated at i/(N-1) (VTK-like presets, vnr format).
TransferFunction build_nodal(std::vector<ColorPoint> colors, std::vector<AlphaPoint> alphas, int n,
                             float lo, float hi, std::string name) {
  sort_points(colors, alphas);
  TransferFunction tf;
  tf.table.resize(size_t(n));
  for (int i = 0; i < n; ++i) {
    const double x = double(i) / double(n - 1);
    const Vec3f c = eval_color(colors, x);
    tf.table[size_t(i)] = Vec4f{c.x, c.y, c.z, eval_alpha(alphas, x)};
  }
  tf.lo = lo;
  tf.hi = hi;
  tf.name = std::move(name);
  return tf;
}

// ---- presets -------------------------------------------------------------------------------------

// Opacity of the VTK peer: 0 up to v = 0.1, then linear to 0.8 at v = 1.
std::vector<AlphaPoint> vtk_opacity() { return {{0.0, 0.0f}, {0.1, 0.0f}, {1.0, 0.8f}}; }

struct Preset {
  const char* name;
  std::vector<ColorPoint> colors;
  std::vector<AlphaPoint> alphas;
};

const std::vector<Preset>& presets() {
  static const std::vector<Preset> p = {
      // The colour and opacity functions of the VTK ray-casting comparison (docs/benchmarks.md
      // "Rendering speed (CPU)"), so both renderers draw the same image.
      {"ramp", {{0.0, {0.0f, 0.0f, 0.3f}}, {0.3, {0.9f, 0.4f, 0.1f}}, {1.0, {1.0f, 1.0f, 0.9f}}}, vtk_opacity()},
      // Grey colour ramp, opacity linear from 0 to 1.
      {"gray", {{0.0, {0.0f, 0.0f, 0.0f}}, {1.0, {1.0f, 1.0f, 1.0f}}}, {{0.0, 0.0f}, {1.0, 1.0f}}},
      // Moreland's diverging cool-warm map (5 of its control colours), the peer's opacity ramp.
      {"cool-warm",
       {{0.0, {0.2298f, 0.2987f, 0.7537f}},
        {0.25, {0.5543f, 0.6901f, 0.9955f}},
        {0.5, {0.8654f, 0.8654f, 0.8654f}},
        {0.75, {0.9567f, 0.5980f, 0.4773f}},
        {1.0, {0.7057f, 0.0156f, 0.1502f}}},
       vtk_opacity()},
      // Black-body style "hot" (matplotlib's break points), the peer's opacity ramp.
      {"hot",
       {{0.0, {0.0416f, 0.0f, 0.0f}}, {0.365, {1.0f, 0.0f, 0.0f}}, {0.746, {1.0f, 1.0f, 0.0f}}, {1.0, {1.0f, 1.0f, 1.0f}}},
       vtk_opacity()},
      // Blue-tinted grey "bone" (matplotlib's break points), the peer's opacity ramp.
      {"bone",
       {{0.0, {0.0f, 0.0f, 0.0f}}, {0.375, {0.3194f, 0.3194f, 0.4444f}}, {0.746, {0.6528f, 0.7778f, 0.7778f}}, {1.0, {1.0f, 1.0f, 1.0f}}},
       vtk_opacity()},
  };
  return p;
}

// ---- JSON helpers --------------------------------------------------------------------------------

double number(const Json& j, const std::string& where) {
  if (!j.is_number()) fail("{}: expected a number, got {}", where, j.type_name());
  const double v = j.get<double>();
  if (!std::isfinite(v)) fail("{}: number is not finite", where);
  return v;
}

double unit_number(const Json& j, const std::string& where) {
  const double v = number(j, where);
  if (v < 0 || v > 1) fail("{}: {} is outside [0, 1]", where, v);
  return v;
}

const Json& member(const Json& obj, const char* key, const std::string& where) {
  if (!obj.is_object()) fail("{}: expected a JSON object, got {}", where, obj.type_name());
  auto it = obj.find(key);
  if (it == obj.end()) fail("{}: missing key \"{}\"", where, key);
  return *it;
}

const Json& array_of(const Json& j, const std::string& where) {
  if (!j.is_array()) fail("{}: expected an array, got {}", where, j.type_name());
  return j;
}

int resolution_of(const Json& j, const std::string& where) {
  const double v = number(j, where);
  if (v != std::floor(v)) fail("{}: resolution {} is not an integer", where, v);
  if (v < 2 || v > kMaxResolution) fail("{}: resolution {} is outside [2, {}]", where, v, kMaxResolution);
  return int(v);
}

// ---- base64 --------------------------------------------------------------------------------------

std::string base64_decode(const std::string& s, const std::string& where) {
  auto value = [](char c) -> int {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    if (c == '+') return 62;
    if (c == '/') return 63;
    return -1;
  };
  std::string out;
  out.reserve(s.size() / 4 * 3);
  uint32_t acc = 0;
  int bits = 0, digits = 0, pad = 0;
  for (size_t i = 0; i < s.size(); ++i) {
    const char c = s[i];
    if (c == ' ' || c == '\n' || c == '\r' || c == '\t') continue;
    if (c == '=') {
      ++pad;
      continue;
    }
    const int v = value(c);
    if (v < 0) {
      if (static_cast<unsigned char>(c) >= 0x20 && static_cast<unsigned char>(c) < 0x7f)
        fail("{}: invalid base64 character '{}' at offset {}", where, c, i);
      fail("{}: invalid base64 byte 0x{:02x} at offset {}", where, static_cast<unsigned char>(c), i);
    }
    if (pad) fail("{}: invalid base64: data after '=' padding at offset {}", where, i);
    acc = (acc << 6) | uint32_t(v);
    bits += 6;
    ++digits;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(char((acc >> bits) & 0xff));
    }
  }
  if (digits % 4 == 1) fail("{}: invalid base64: truncated data ({} digits)", where, digits);
  if (pad > 2 || (pad && (digits + pad) % 4 != 0)) fail("{}: invalid base64 padding", where);
  return out;
}

std::string base64_encode(const std::string& bytes) {
  static const char* digits = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  for (size_t i = 0; i < bytes.size(); i += 3) {
    const size_t n = std::min<size_t>(3, bytes.size() - i);
    uint32_t v = 0;
    for (size_t k = 0; k < 3; ++k) v = (v << 8) | (k < n ? uint8_t(bytes[i + k]) : 0u);
    for (size_t k = 0; k < 4; ++k) out.push_back(k <= n ? digits[(v >> (18 - 6 * k)) & 63] : '=');
  }
  return out;
}

void store_f32_le(char* p, float f) {
  uint32_t u;
  std::memcpy(&u, &f, 4);
  if constexpr (std::endian::native == std::endian::big) u = __builtin_bswap32(u);
  std::memcpy(p, &u, 4);
}

float load_f32_le(const char* p) {
  uint32_t u;
  std::memcpy(&u, p, 4);
  if constexpr (std::endian::native == std::endian::big) u = __builtin_bswap32(u);
  float f;
  std::memcpy(&f, &u, 4);
  return f;
}

// ---- instantvnr TF object ------------------------------------------------------------------------

// "alphaArray": base64 of little-endian float32 opacities in [0, 1].
std::vector<float> alpha_array_of(const Json& arr, const std::string& where) {
  const std::string w = where + ": alphaArray";
  const Json& enc = member(arr, "encoding", w);
    if (!enc.is_string()) fail("{}: encoding must be a string", w);
  if (enc.get<std::string>() != "BASE64")
    fail("{}: encoding \"{}\" is not supported (only \"BASE64\")", w, enc.get<std::string>());
  const Json& data = member(arr, "data", w);
  if (!data.is_string()) fail("{}: data must be a base64 string", w);
  const std::string bytes = base64_decode(data.get<std::string>(), w);
  if (bytes.size() % 4 != 0) fail("{}: {} decoded bytes is not a whole number of float32 values", w, bytes.size());
  const size_t count = bytes.size() / 4;
  if (count < 2) fail("{}: {} entries; a table needs at least 2", w, count);
  if (count > size_t(kMaxResolution)) fail("{}: {} entries; at most {} are allowed", w, count, kMaxResolution);
  std::vector<float> alpha_array(count);
  for (size_t i = 0; i < count; ++i) {
    const float a = load_f32_le(bytes.data() + 4 * i);
    if (!std::isfinite(a)) fail("{}: entry {} is not finite", w, i);
    if (a < 0 || a > 1) fail("{}: entry {} = {} is outside [0, 1]", w, i, a);
    alpha_array[i] = a;
  }
  return alpha_array;
}

// The elements of the JSON array `arr` (named `w` in errors), each read by element(value, "w[k]").
template <class T, class Element>
std::vector<T> elements_of(const Json& arr, const std::string& w, const Element& element) {
  std::vector<T> out;
  for (size_t k = 0; k < array_of(arr, w).size(); ++k) out.push_back(element(arr[k], fmt::format("{}[{}]", w, k)));
  return out;
}

// "colorControls": [{"position": p, "color": {"r", "g", "b"}}, ...], all in [0, 1].
std::vector<ColorPoint> color_controls_of(const Json& arr, const std::string& where) {
  return elements_of<ColorPoint>(arr, where + ": colorControls", [](const Json& cc, const std::string& wk) {
    const double p = unit_number(member(cc, "position", wk), wk + ".position");
    const Json& col = member(cc, "color", wk);
    const float r = float(unit_number(member(col, "r", wk + ".color"), wk + ".color.r"));
    const float g = float(unit_number(member(col, "g", wk + ".color"), wk + ".color.g"));
    const float b = float(unit_number(member(col, "b", wk + ".color"), wk + ".color.b"));
    return ColorPoint{p, Vec3f{r, g, b}};
  });
}

// "opacityControl": [{"position": {"x": value, "y": opacity}}, ...], all in [0, 1].
std::vector<AlphaPoint> opacity_controls_of(const Json& arr, const std::string& where) {
  return elements_of<AlphaPoint>(arr, where + ": opacityControl", [](const Json& oc, const std::string& wk) {
    const Json& pos = member(oc, "position", wk);
    const double x = unit_number(member(pos, "x", wk + ".position"), wk + ".position.x");
    const double a = unit_number(member(pos, "y", wk + ".position"), wk + ".position.y");
    return AlphaPoint{x, float(a)};
  });
}

struct GaussianBump {
  double mean, sigma, height;
};

// "gaussianObjects": [{"mean", "sigma" > 0, "heightFactor"}, ...].
std::vector<GaussianBump> gaussian_objects_of(const Json& arr, const std::string& where) {
  return elements_of<GaussianBump>(arr, where + ": gaussianObjects", [](const Json& g, const std::string& wk) {
    const double mean = number(member(g, "mean", wk), wk + ".mean");
    const double sigma = number(member(g, "sigma", wk), wk + ".sigma");
    const double h = number(member(g, "heightFactor", wk), wk + ".heightFactor");
    if (!(sigma > 0)) fail("{}.sigma: {} must be positive", wk, sigma);
    return GaussianBump{mean, sigma, h};
  });
}

// docs/MODEL_FORMAT.md section 3: the keys are read in this order, so the first bad one is reported.
TransferFunction tf_from_instantvnr(const Json& j, const std::string& where) {
  if (!j.is_object()) fail("{}: transfer function must be a JSON object, got {}", where, j.type_name());
  int n = kDefaultResolution;
  if (auto it = j.find("resolution"); it != j.end()) n = resolution_of(*it, where + ": resolution");
  std::vector<float> alpha_array;
  if (auto it = j.find("alphaArray"); it != j.end()) {
    alpha_array = alpha_array_of(*it, where);
    n = int(alpha_array.size());  // the alphaArray length overrides "resolution"
  }
  std::vector<ColorPoint> colors;
  if (auto it = j.find("colorControls"); it != j.end()) colors = color_controls_of(*it, where);
  std::vector<AlphaPoint> opacity;
  const bool has_opacity = j.contains("opacityControl");
  if (has_opacity) opacity = opacity_controls_of(j["opacityControl"], where);
  std::vector<GaussianBump> gaussians;
  if (auto it = j.find("gaussianObjects"); it != j.end()) gaussians = gaussian_objects_of(*it, where);

  sort_points(colors, opacity);
  TransferFunction tf;
  tf.table.resize(size_t(n));
  const double sqrt_2pi = std::sqrt(2.0 * 3.14159265358979323846);
  for (int i = 0; i < n; ++i) {
    const double xc = (double(i) + 0.5) / double(n);  // colours and Gaussians: cell centres
    const Vec3f c = eval_color(colors, xc);
    float a = alpha_array.empty() ? 0.0f : alpha_array[size_t(i)];
    for (const GaussianBump& g : gaussians) {
      const double d = xc - g.mean;
      const double v = g.height / (g.sigma * sqrt_2pi) * std::exp(-d * d / (2 * g.sigma * g.sigma));
      a = std::max(a, float(std::clamp(v, 0.0, 1.0)));
    }
    if (has_opacity) a = std::max(a, eval_alpha(opacity, double(i) / double(n - 1)));  // nodes
    tf.table[size_t(i)] = Vec4f{c.x, c.y, c.z, a};
  }
  // instantvnr's post-step: near-transparent end entries become fully transparent.
  if (tf.table.front().w < 0.01f) tf.table.front().w = 0;
  if (tf.table.back().w < 0.01f) tf.table.back().w = 0;
  tf.lo = 0;
  tf.hi = 1;
  tf.name = where;
  return tf;
}

// ---- vnr simple format ---------------------------------------------------------------------------

TransferFunction tf_from_vnr(const Json& j, const std::string& where) {
  for (auto it = j.begin(); it != j.end(); ++it) {
    const std::string& k = it.key();
    if (k != "colors" && k != "opacities" && k != "resolution" && k != "range")
      fail("{}: unknown transfer-function key \"{}\" (allowed: colors, opacities, resolution, range)", where, k);
  }
  // [[v, c1, ...], ...]: each point an array of names.size() numbers in [0,1].
  auto points = [&](const char* key, const std::vector<const char*>& names, const char* shape) {
    const std::string w = where + ": " + key;
    const Json& arr = array_of(member(j, key, where), w);
    if (arr.empty()) fail("{}: needs at least one {} point", w, shape);
    std::vector<std::vector<double>> out;
    for (size_t k = 0; k < arr.size(); ++k) {
      const std::string wk = fmt::format("{}[{}]", w, k);
      if (!arr[k].is_array() || arr[k].size() != names.size()) fail("{}: expected {}", wk, shape);
      std::vector<double> p;
      for (size_t c = 0; c < names.size(); ++c) p.push_back(unit_number(arr[k][c], wk + " " + names[c]));
      out.push_back(p);
    }
    return out;
  };
  std::vector<ColorPoint> colors;
  for (const auto& p : points("colors", {"v", "r", "g", "b"}, "[v, r, g, b]"))
    colors.push_back({p[0], Vec3f{float(p[1]), float(p[2]), float(p[3])}});
  std::vector<AlphaPoint> alphas;
  for (const auto& p : points("opacities", {"v", "a"}, "[v, a]")) alphas.push_back({p[0], float(p[1])});
  int n = kDefaultResolution;
  if (auto it = j.find("resolution"); it != j.end()) n = resolution_of(*it, where + ": resolution");
  float lo = 0, hi = 1;
  if (auto it = j.find("range"); it != j.end()) {
    const std::string w = where + ": range";
    if (!it->is_array() || it->size() != 2) fail("{}: expected [lo, hi]", w);
    lo = float(number((*it)[0], w + " lo"));
    hi = float(number((*it)[1], w + " hi"));
    if (!(lo < hi)) fail("{}: lo {} must be below hi {}", w, lo, hi);
  }
  return build_nodal(std::move(colors), std::move(alphas), n, lo, hi, where);
}

bool has_any(const Json& j, std::initializer_list<const char*> keys) {
  for (const char* k : keys)
    if (j.contains(k)) return true;
  return false;
}

std::string preset_list() {
  std::string s;
  for (const auto& p : presets()) s += (s.empty() ? "" : ", ") + std::string(p.name);
  return s;
}

// The preset called `name` (any case); fails naming the presets.
const Preset& find_preset(const std::string& name) {
  for (const auto& p : presets())
    if (iequals(name, p.name)) return p;
  fail("unknown transfer-function preset \"{}\" (presets: {})", name, preset_list());
}

}  // namespace

std::vector<std::string> tf_preset_names() {
  std::vector<std::string> names;
  for (const auto& p : presets()) names.emplace_back(p.name);
  return names;
}

bool is_tf_preset(const std::string& name) {
  for (const auto& p : presets())
    if (iequals(name, p.name)) return true;
  return false;
}

TransferFunction tf_preset(const std::string& name) {
  const Preset& p = find_preset(name);
  return build_nodal(p.colors, p.alphas, kDefaultResolution, 0, 1, p.name);
}

TransferFunction tf_from_json(const Json& j, const std::string& where) {
  if (!j.is_object()) fail("{}: transfer function must be a JSON object, got {}", where, j.type_name());
  if (j.contains("view") || j.contains("dataSource")) {  // a whole instantvnr scene
    const Json* v = nullptr;
    if (auto it = j.find("view"); it != j.end() && it->is_object())
      if (auto vol = it->find("volume"); vol != it->end() && vol->is_object())
        if (auto t = vol->find("transferFunction"); t != vol->end()) v = &*t;
    if (!v) fail("{}: instantvnr scene has no view.volume.transferFunction", where);
    TransferFunction tf = tf_from_instantvnr(*v, where + ": view.volume.transferFunction");
    tf.name = where;
    return tf;
  }
  if (auto it = j.find("transferFunction"); it != j.end()) {  // standalone instantvnr TF file
    TransferFunction tf = tf_from_instantvnr(*it, where + ": transferFunction");
    tf.name = where;
    return tf;
  }
  const bool ivnr = has_any(j, {"alphaArray", "colorControls", "opacityControl", "gaussianObjects"});
  const bool simple = has_any(j, {"colors", "opacities", "range"});
  if (ivnr && simple)
    fail("{}: mixes instantvnr keys (alphaArray, colorControls, opacityControl, gaussianObjects) with vnr keys "
         "(colors, opacities, range)",
         where);
  if (ivnr) return tf_from_instantvnr(j, where);
  if (simple) return tf_from_vnr(j, where);
  std::string keys;
  for (auto it = j.begin(); it != j.end(); ++it) keys += (keys.empty() ? "" : ", ") + it.key();
  fail("{}: not a transfer function (keys: {}); expected vnr's \"colors\"/\"opacities\", an instantvnr "
       "\"alphaArray\"/\"colorControls\"/\"gaussianObjects\"/\"opacityControl\" object, a \"transferFunction\" "
       "object or an instantvnr scene",
       where, keys.empty() ? "none" : keys);
}

TransferFunction load_transfer_function(const std::string& file_or_preset) {
  if (is_tf_preset(file_or_preset)) return tf_preset(file_or_preset);
  if (!file_exists(file_or_preset))
    fail("transfer function '{}' is neither a preset ({}) nor an existing file", file_or_preset, preset_list());
  TransferFunction tf = tf_from_json(parse_json_file(file_or_preset), file_or_preset);
  tf.name = file_or_preset;
  return tf;
}

TransferFunction tf_from_points(std::vector<TfColorPoint> colors, std::vector<TfAlphaPoint> alphas, int n, float lo,
                                float hi, std::string name) {
  if (n < 2 || n > kMaxResolution) fail("transfer function: resolution {} is outside [2, {}]", n, kMaxResolution);
  if (!(lo < hi)) fail("transfer function: window lo {} must be below hi {}", lo, hi);
  return build_nodal(std::move(colors), std::move(alphas), n, lo, hi, std::move(name));
}

std::vector<TfAlphaPoint> tf_preset_opacity(const std::string& name) { return find_preset(name).alphas; }

Json tf_to_instantvnr_json(const TransferFunction& tf) {
  const int n = int(tf.table.size());
  if (n < 2) fail("transfer function: needs at least 2 entries");
  const TfView view = view_of(tf);
  const bool whole_range = tf.lo == 0 && tf.hi == 1;
  std::string alpha_bytes(size_t(n) * 4, '\0');
  Json colors = Json::array();
  for (int i = 0; i < n; ++i) {
    const Vec4f e = whole_range ? tf.table[size_t(i)] : tf_lookup(view, float(double(i) / double(n - 1)));
    store_f32_le(alpha_bytes.data() + 4 * i, std::clamp(e.w, 0.0f, 1.0f));
    // The reader evaluates colours at cell centres (i + 0.5) / n: a point exactly there gives entry i.
    colors.push_back({{"position", (double(i) + 0.5) / double(n)},
                      {"color", {{"r", std::clamp(e.x, 0.0f, 1.0f)}, {"g", std::clamp(e.y, 0.0f, 1.0f)}, {"b", std::clamp(e.z, 0.0f, 1.0f)}}}});
  }
  Json t = {{"resolution", n},
            {"alphaArray", {{"encoding", "BASE64"}, {"data", base64_encode(alpha_bytes)}}},
            {"colorControls", std::move(colors)}};
  return Json{{"transferFunction", std::move(t)}};
}

}  // namespace vnr
