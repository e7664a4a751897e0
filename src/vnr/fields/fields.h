#pragma once
// The fields a renderer draws, wired above the render layer: the ground-truth grid (GridField over a
// GridView) and a trained network (NetworkField over a Network and its PointEvaluator), and the
// factory of a renderer on either backend. render sees them only as the Field interface (the batched
// query and the in-shader hand-over of their point function), render_cuda as a GpuFieldSource.
#include <memory>
#include "vnr/device.h"
#include "vnr/nn/network.h"
#include "vnr/nn/point_eval.h"
#include "vnr/render/field.h"
#include "vnr/render/renderer.h"
#include "vnr/render_cuda/gpu_renderer.h"
#include "vnr/volume/volume.h"

namespace vnr {

// A field every backend can draw: render's Field plus what a GPU renderer copies to the GPU.
class RenderableField : public Field {
public:
  virtual GpuFieldSource gpu_source() const = 0;
  // One value at u in [0,1)^3 (what the in-shader strategy samples; the brick cache's exact misses).
  virtual float point(float x, float y, float z) const = 0;
};

class GridField final : public RenderableField {
public:
  explicit GridField(GridView g) : g_(g) {}
  Int3 dims() const override { return Int3{g_.nx, g_.ny, g_.nz}; }
  const char* kind() const override { return "grid"; }
  void query(const float* x, const float* y, const float* z, int64_t n, float* out) const override;
  int64_t render_inshader(const InshaderJob& job) const override;  // SIMD ray packets where they apply
  GpuFieldSource gpu_source() const override { return GpuFieldSource{g_, nullptr, dims()}; }
  float point(float x, float y, float z) const override { return grid_lookup(g_, x, y, z); }
  const GridView& view() const { return g_; }

private:
  GridView g_;
};

// A network's point function for the in-shader strategy (one sample at a time inside a ray's loop).
struct NetworkPointFn {
  const PointEvaluator* eval;
  float operator()(float x, float y, float z) const { return eval->eval(x, y, z); }
};

class NetworkField final : public RenderableField {
public:
  NetworkField(const Network& net, Int3 dims) : net_(net), dims_(dims), point_(net) {}
  Int3 dims() const override { return dims_; }
  const char* kind() const override { return "network"; }
  void query(const float* x, const float* y, const float* z, int64_t n, float* out) const override;
  int64_t render_inshader(const InshaderJob& job) const override;
  GpuFieldSource gpu_source() const override { return GpuFieldSource{GridView{}, &net_, dims_}; }
  float point(float x, float y, float z) const override { return point_.eval(x, y, z); }
  NetworkPointFn point_fn() const { return NetworkPointFn{&point_}; }
  const Network& network() const { return net_; }

private:
  const Network& net_;
  Int3 dims_;
  PointEvaluator point_;
};

// The renderer of a device: a CpuRenderer, or a GpuRenderer (the field's grid or network copied to
// the GPU; mlp = its streaming inference path). field, mc and tf must outlive a CpuRenderer.
std::unique_ptr<FrameRenderer> make_renderer(Device device, const RenderableField& field, Vec3f box,
                                             const MacroCells& mc, const TransferFunction& tf, const Camera& cam,
                                             const RenderOptions& opt, cuda::MlpPath mlp = cuda::MlpPath::Auto);

}  // namespace vnr
