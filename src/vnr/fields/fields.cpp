#include "vnr/fields/fields.h"
#include <atomic>
#include <cstring>
#include "vnr/core/parallel.h"
#include "vnr/fields/grid_packets.h"
#include "vnr/render/inshader.h"

namespace vnr {

int64_t run_inshader_grid(const InshaderJob& job, const GridView& g) {
  const RenderParams& p = *job.params;
  if (job.ray_packets && job.mode == RenderMode::RayMarch && grid_packets_apply(p, g)) {
    std::atomic<int64_t> samples{0}, next_tile{0};
    parallel_threads([&](int, int) {
      const TileCursor tiles{p.cam.width, p.cam.height, kInshaderTile, 0, 1, &next_tile};
      samples += march_grid_packets(p, g, tiles, job.pixels);
    });
    return samples.load();
  }
  return run_inshader(job, GridPointFn{g});
}

void GridField::query(const float* x, const float* y, const float* z, int64_t n, float* out) const {
  parallel_for_claimed(n, 4096, [&](int64_t b, int64_t e) { grid_lookup_batch(g_, x + b, y + b, z + b, e - b, out + b); });
}

int64_t GridField::render_inshader(const InshaderJob& job) const { return run_inshader_grid(job, g_); }

void NetworkField::query(const float* x, const float* y, const float* z, int64_t n, float* out) const {
  net_.infer_fn(
      n,
      [&](int64_t first, int64_t count, float* px, float* py, float* pz) {  // whole chunks: three copies
        std::memcpy(px, x + first, sizeof(float) * size_t(count));
        std::memcpy(py, y + first, sizeof(float) * size_t(count));
        std::memcpy(pz, z + first, sizeof(float) * size_t(count));
      },
      out);
}

int64_t NetworkField::render_inshader(const InshaderJob& job) const { return run_inshader(job, point_fn()); }

std::unique_ptr<FrameRenderer> make_renderer(Device device, const RenderableField& field, Vec3f box,
                                             const MacroCells& mc, const TransferFunction& tf, const Camera& cam,
                                             const RenderOptions& opt, cuda::MlpPath mlp) {
  if (device == Device::Cuda) return std::make_unique<GpuRenderer>(field.gpu_source(), box, mc, tf, cam, opt, mlp);
  return std::make_unique<CpuRenderer>(field, box, mc, tf, cam, opt);
}

}  // namespace vnr
