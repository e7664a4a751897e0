#pragma once
// A multi-brick model as a field (train/bricks.h; docs/MODEL_FORMAT.md "Multi-brick models"): each
// sample blends the networks of the bricks whose trained box holds it, with core/brick_box.h's weights,
// so rays cross bricks without seams. CPU only: the GPU draws a multi-brick model from its decode
// (api/model_field.h).
#include <memory>
#include <vector>
#include "vnr/core/brick_box.h"
#include "vnr/fields/fields.h"

namespace vnr {

class BrickedField final : public RenderableField {
public:
  // nets[b] is brick b's network (every brick must be present); layout gives the boxes.
  BrickedField(std::vector<const Network*> nets, BrickLayout layout);
  Int3 dims() const override { return layout_.dims; }
  const char* kind() const override { return "network"; }
  void query(const float* x, const float* y, const float* z, int64_t n, float* out) const override;
  int64_t render_inshader(const InshaderJob& job) const override;
  GpuFieldSource gpu_source() const override;
  float point(float x, float y, float z) const override;  // one blended value (what the in-shader strategy samples)

private:
  std::vector<const Network*> nets_;
  BrickLayout layout_;
  std::vector<std::unique_ptr<PointEvaluator>> points_;
};

}  // namespace vnr
