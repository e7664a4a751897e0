#pragma once
// The field every integrator reads, as the render layer sees it: a batched query (the streaming
// strategy) and a per-frame hand-over to the in-shader strategy with the field's own point function.
// The concrete fields (the ground-truth grid, a trained network) are wired above this layer
// (online/fields.h), so render knows neither the network nor its evaluator.
#include <cstdint>
#include "vnr/math.h"

namespace vnr {

struct InshaderJob;   // render/inshader.h
struct RenderParams;  // render/integrators.h

class Field {
public:
  virtual ~Field() = default;
  virtual Int3 dims() const = 0;
  virtual const char* kind() const = 0;  // "grid", "network" or "cache"
  // Batched query (parallel inside): out[i] = field(x[i], y[i], z[i]), normalised coordinates in
  // [0,1)^3 in, normalised values out.
  virtual void query(const float* x, const float* y, const float* z, int64_t n, float* out) const = 0;
  // Renders one in-shader frame: implementations call run_inshader(job, point_fn) of render/inshader.h
  // with their point function, so the per-sample calls inline (one virtual call per frame).
  // Returns the number of field samples taken.
  virtual int64_t render_inshader(const InshaderJob& job) const = 0;
  // Called by a renderer before each frame with that frame's parameters (camera, frame number): a
  // field that keeps state for the view (the brick cache: levels of detail, decoding) updates it here,
  // before any query of the frame. Nothing for fields without such state.
  virtual void begin_frame(const RenderParams&) const {}
};

}  // namespace vnr
