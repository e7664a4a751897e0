// GpuRenderer in a build without CUDA (VNR_CUDA=OFF): every entry point fails with one line.
#include "vnr/error.h"
#include "vnr/render_cuda/gpu_renderer.h"

namespace vnr {
namespace {
[[noreturn]] void not_built() {
  fail("this vnr was built without the CUDA backend (configure with -DVNR_CUDA=ON and the CUDA toolkit); "
       "use --device cpu");
}
}  // namespace

struct GpuRenderer::Impl {};
GpuRenderer::GpuRenderer(const GpuFieldSource&, Vec3f, const MacroCells&, const TransferFunction&, const Camera&,
                         const RenderOptions&, cuda::MlpPath) {
  not_built();
}
GpuRenderer::~GpuRenderer() = default;
void GpuRenderer::render_frame(uint32_t, Image&, RenderStats*) { not_built(); }
void GpuRenderer::render_frame_resident(uint32_t, RenderStats*) { not_built(); }
void GpuRenderer::render_mean_rgba8(uint32_t, std::vector<uint8_t>&) { not_built(); }
void GpuRenderer::set_camera(const Camera&) { not_built(); }
bool GpuRenderer::refresh_network(const MacroCells&, const void*) { not_built(); }
void GpuRenderer::set_transfer_function(const TransferFunction&) { not_built(); }
void GpuRenderer::set_ranges(const ValueRangeGrid&) { not_built(); }
std::vector<float> GpuRenderer::max_opacity() { not_built(); }
cuda::MlpPath GpuRenderer::mlp_path() const { not_built(); }
void GpuRenderer::set_inference_slab(int64_t) { not_built(); }
bool GpuRenderer::inshader_weights_shared() const { not_built(); }
ValueRangeGrid gpu_value_ranges_from_grid(const GridView&, int) { not_built(); }

}  // namespace vnr
