#include "vnr/render_cuda/gpu_renderer.h"

namespace vnr {

std::unique_ptr<FrameRenderer> make_renderer(Device device, const Field& field, Vec3f box, const MacroCells& mc,
                                             const TransferFunction& tf, const Camera& cam, const RenderOptions& opt,
                                             cuda::MlpPath mlp) {
  if (device == Device::Cuda) return std::make_unique<GpuRenderer>(field, box, mc, tf, cam, opt, mlp);
  return std::make_unique<CpuRenderer>(field, box, mc, tf, cam, opt);
}

}  // namespace vnr
