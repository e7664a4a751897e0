#include "vnr/fields/bricked_field.h"
#include "vnr/error.h"
#include "vnr/core/parallel.h"
#include "vnr/render/inshader.h"

namespace vnr {

namespace {
// The in-shader point function: one blended sample, each brick's PointEvaluator per point.
struct BrickedPointFn {
  const BrickLayout* layout;
  const std::unique_ptr<PointEvaluator>* points;
  float operator()(float x, float y, float z) const {
    return layout->blend_point(x, y, z, [&](int b, float lx, float ly, float lz) { return points[b]->eval(lx, ly, lz); });
  }
};
}  // namespace

BrickedField::BrickedField(std::vector<const Network*> nets, BrickLayout layout)
    : nets_(std::move(nets)), layout_(std::move(layout)) {
  if (nets_.size() != layout_.owned.size()) fail("a bricked field needs {} networks, got {}", layout_.owned.size(), nets_.size());
  for (size_t b = 0; b < nets_.size(); ++b) {
    if (!nets_[b]) fail("brick {} is not loaded: rendering needs every brick", b);
    points_.push_back(std::make_unique<PointEvaluator>(*nets_[b]));
  }
}

void BrickedField::query(const float* x, const float* y, const float* z, int64_t n, float* out) const {
  layout_.blend_batch(
      n,
      [&](int64_t i, float* px, float* py, float* pz) {
        *px = x[i];
        *py = y[i];
        *pz = z[i];
      },
      out, [&](int b, const float* local, int64_t m, float* vals) { nets_[size_t(b)]->infer(local, m, vals); });
}

int64_t BrickedField::render_inshader(const InshaderJob& job) const {
  return run_inshader(job, BrickedPointFn{&layout_, points_.data()});
}

float BrickedField::point(float x, float y, float z) const { return BrickedPointFn{&layout_, points_.data()}(x, y, z); }

GpuFieldSource BrickedField::gpu_source() const {
  fail("BrickedField draws on the CPU; the GPU draws a multi-brick model from its decode (DecodedModelField)");
}

}  // namespace vnr
