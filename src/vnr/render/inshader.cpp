#include "vnr/render/inshader.h"
#include "vnr/render/grid_packets.h"

namespace vnr {

int64_t run_inshader_grid(const InshaderJob& job, const GridView& g) {
  const RenderParams& p = *job.params;
  if (job.ray_packets && job.mode == RenderMode::RayMarch && grid_packets_apply(p, g)) {
    std::atomic<int64_t> samples{0};
    parallel_threads([&](int t, int nt) {
      samples += march_grid_packets(p, g, TileCursor{p.cam.width, p.cam.height, kInshaderTile, t, nt}, job.pixels);
    });
    return samples.load();
  }
  return run_inshader(job, GridPointFn{g});
}

}  // namespace vnr
