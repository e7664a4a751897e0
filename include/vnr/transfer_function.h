#pragma once
// Transfer functions (docs/semantics.md B.5, the instantvnr TF format): a table of N RGBA entries, entry
// i at normalised value lo + i/(N-1) * (hi - lo), linearly interpolated, clamped at the ends. Colour
// is straight (not premultiplied); alpha is the opacity per unit step (one voxel).
#include <string>
#include <vector>
#include "vnr/json.h"
#include "vnr/math.h"

namespace vnr {

struct TransferFunction {
  std::vector<Vec4f> table;  // N >= 2 entries
  float lo = 0, hi = 1;      // window over normalised values [0,1] that the table spans
  std::string name;          // preset name or file, for reports
};

// Built-in presets by name (see tf_preset_names()); "ramp" is the VTK peer's transfer function.
std::vector<std::string> tf_preset_names();
bool is_tf_preset(const std::string& name);
TransferFunction tf_preset(const std::string& name);

// Control points of a colour or opacity function over the table's own [0, 1] (0 = lo, 1 = hi).
struct TfColorPoint {
  double x;
  Vec3f c;
};
struct TfAlphaPoint {
  double x;
  float a;
};
// A node-centred table of n entries (entry i = both piecewise-linear functions at i/(n-1), constant
// beyond the end points; what presets and vnr's simple format build); points in any order.
TransferFunction tf_from_points(std::vector<TfColorPoint> colors, std::vector<TfAlphaPoint> alphas, int n, float lo,
                                float hi, std::string name);
// A preset's opacity control points (tf_from_points(..., preset colours, these) == tf_preset(name)).
std::vector<TfAlphaPoint> tf_preset_opacity(const std::string& name);

// Parses any of: an instantvnr transfer-function object ({"alphaArray", "colorControls",
// "opacityControl", "gaussianObjects", "resolution"}), a standalone instantvnr TF file
// ({"transferFunction": {...}}), a whole instantvnr scene (view.volume.transferFunction), or vnr's
// simple format {"colors": [[v, r, g, b], ...], "opacities": [[v, a], ...], "resolution": N,
// "range": [lo, hi]}. `where` names the source in error messages.
TransferFunction tf_from_json(const Json& j, const std::string& where);
// A standalone instantvnr TF file ({"transferFunction": {"alphaArray", "colorControls", "resolution"}})
// that tf_from_json reads back to the same table: the alphas exactly, the colours as one control
// point per entry at the reader's colour positions. A window other than [0, 1] is baked in (the format
// has none): entry i then holds tf at normalised value i/(n-1). instantvnr zeroes end alphas below 0.01.
Json tf_to_instantvnr_json(const TransferFunction& tf);
// A preset name, or a JSON file in one of the formats above.
TransferFunction load_transfer_function(const std::string& file_or_preset);

}  // namespace vnr
