// `vnr bench render`'s table (include/vnr/benchmark.h): every mode x strategy x macro-cell setting timed
// over the same orbit, and the K sweep of streaming ray marching.
#include <fmt/format.h>
#include "vnr/benchmark.h"
#include "vnr/error.h"

namespace vnr {

std::vector<RenderBenchRow> render_benchmark(Renderer& r, const std::vector<RenderMode>& modes,
                                             const std::vector<std::string>& strategies, MacroCellMode with,
                                             const RenderOrbit& orbit, const BrickCacheSettings& cache,
                                             const std::function<void(const RenderBenchRow&)>& row) {
  struct Cell {
    RenderMode mode;
    RenderStrategy strategy;
    MacroCellMode mc;
    bool cache;
  };
  std::vector<Cell> cells;  // every strategy parsed before the first cell is timed
  for (RenderMode m : modes)
    for (const std::string& s : strategies)
      for (MacroCellMode mc : {MacroCellMode::Off, with})
        cells.push_back(s == "cache" ? Cell{m, fastest_render_strategy("cache", r.device() == Device::Cuda, m), mc, true}
                                     : Cell{m, parse_render_strategy(s), mc, false});
  const RenderOptions base = r.options();
  std::vector<RenderBenchRow> rows;
  for (const Cell& cell : cells) {
    RenderOptions o = base;
    o.mode = cell.mode;
    o.strategy = cell.strategy;
    RenderStats tot;
    RenderBenchRow out;
    out.fps = orbit_frame_rate(r, o, cell.mc, orbit, cell.cache ? std::optional(cache) : std::nullopt, &tot);
    out.mode = cell.mode;
    out.strategy = cell.cache ? fmt::format("cache ({})", render_strategy_name(cell.strategy))
                              : render_strategy_name(cell.strategy);
    out.macrocells = cell.mc;
    out.field_samples_per_second = double(tot.field_samples) / tot.seconds;
    out.host_syncs_per_frame = double(tot.host_syncs) / tot.frames;
    out.iterations_per_frame = double(tot.iterations) / tot.frames;
    rows.push_back(out);
    if (row) row(out);
  }
  r.set_options(base);
  r.set_cache(std::nullopt);
  return rows;
}

std::vector<TuneKRow> tune_samples_per_iteration(Renderer& r, const std::vector<int>& ks, MacroCellMode with,
                                                 const RenderOrbit& orbit,
                                                 const std::function<void(const TuneKRow&)>& row) {
  const RenderOptions base = r.options();
  std::vector<TuneKRow> rows;
  for (int k : ks) {
    if (k < 1 || k > 1024) fail("samples per iteration must be in [1, 1024] (got {})", k);
    RenderOptions o = base;
    o.mode = RenderMode::RayMarch;
    o.strategy = RenderStrategy::Streaming;
    o.samples_per_iteration = k;
    RenderStats tot;
    TuneKRow out;
    out.k = k;
    out.fps = orbit_frame_rate(r, o, with, orbit, std::nullopt, &tot);
    out.field_samples_per_second = double(tot.field_samples) / tot.seconds;
    out.samples_per_frame = double(tot.field_samples) / tot.frames;
    rows.push_back(out);
    if (row) row(out);
  }
  r.set_options(base);
  return rows;
}

}  // namespace vnr
