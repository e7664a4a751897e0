// vnr bench render: the paper's frame-rate table for one model or volume -- frames/s of
// {ray marching, shadows, path tracing} x {in-shader, streaming} x {without, with macro-cells} -- and
// how much of the field's raw batched query rate each renderer keeps. The camera orbits the volume
// (360 degrees over the timed frames, like the VTK peer) so every cell sees the same views.
#include <chrono>
#include <cstdio>
#include "cli.h"
#include "render_setup.h"
#include "vnr/benchmark.h"
#include "vnr/error.h"
#include "vnr/threads.h"
#include "vnr/progress.h"

namespace vnr::cli {

namespace {

std::vector<std::string> split_list(const std::string& s) {
  std::vector<std::string> out;
  size_t b = 0;
  while (b <= s.size()) {
    size_t e = s.find(',', b);
    if (e == std::string::npos) e = s.size();
    if (e > b) out.push_back(s.substr(b, e - b));
    b = e + 1;
  }
  return out;
}

// --tune-k: streaming ray-marching frames/s for each K, printed as a table and returned as report rows.
Json tune_k_rows(Renderer& r, MacroCellMode with, const RenderOrbit& orbit, const std::vector<std::string>& list) {
  std::vector<int> ks;
  for (const std::string& k : list) {
    size_t used = 0;
    int v = 0;
    try {
      v = std::stoi(k, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != k.size()) fail("--tune-k expects a list of whole numbers, got '{}'", k);
    ks.push_back(v);
  }
  std::printf("| K | frames/s | field samples/s (M) | samples/frame (M) |\n|---|---|---|---|\n");
  Json rows = Json::array();
  tune_samples_per_iteration(r, ks, with, orbit, [&](const TuneKRow& t) {
    std::printf("| %d | %.2f | %.2f | %.2f |\n", t.k, t.fps, t.field_samples_per_second / 1e6, t.samples_per_frame / 1e6);
    std::fflush(stdout);
    rows.push_back({{"k", t.k}, {"fps", t.fps}, {"field_samples_per_second", t.field_samples_per_second}});
  });
  return rows;
}

// The table: every mode x strategy, without and with macro-cells; `raw` = the field's batched query rate.
Json table_rows(Renderer& r, MacroCellMode with, const RenderOrbit& orbit, const BrickCacheSettings& cache,
                double raw, const std::vector<std::string>& modes, const std::vector<std::string>& strategies) {
  std::vector<RenderMode> parsed;
  for (const std::string& m : modes) parsed.push_back(parse_render_mode(m));
  std::printf("| mode | strategy | macro-cells | frames/s | field samples/s (M) | of raw query rate | host syncs/frame |\n"
              "|---|---|---|---|---|---|---|\n");
  Json rows = Json::array();
  render_benchmark(r, parsed, strategies, with, orbit, cache, [&](const RenderBenchRow& b) {
    const double sps = b.field_samples_per_second;
    std::printf("| %s | %s | %s | %.2f | %.2f | %s | %.0f |\n", render_mode_name(b.mode), b.strategy.c_str(),
                macrocell_mode_name(b.macrocells), b.fps, sps / 1e6,
                raw > 0 ? fmt::format("{:.0f}%", 100 * sps / raw).c_str() : "-", b.host_syncs_per_frame);
    std::fflush(stdout);
    rows.push_back({{"mode", render_mode_name(b.mode)},
                    {"strategy", b.strategy},
                    {"macrocells", macrocell_mode_name(b.macrocells)},
                    {"fps", b.fps},
                    {"field_samples_per_second", sps},
                    {"host_syncs_per_frame", b.host_syncs_per_frame},
                    {"iterations_per_frame", b.iterations_per_frame}});
  });
  return rows;
}

}  // namespace

void add_bench_render(CLI::App& bench) {
  struct Args {
    std::string input, report, modes = "raymarch,shadow,pathtrace", strategies,
                                  macrocells, tune_k;
    int frames = 6, warmup = 1;
    RenderArgs r;
    VolumeArgs vol;
  };
  auto a = std::make_shared<Args>();
  a->r.s.width = a->r.s.height = 512;
  CLI::App* c = bench.add_subcommand("render", "frames/s of every integrator x strategy x macro-cell setting");
  c->add_option("input", a->input, "model (.vnr, instantvnr BSON) or volume")->required();
  c->add_option("--frames", a->frames, "timed frames per cell (the camera orbits 360 degrees over them)")
      ->capture_default_str();
  c->add_option("--warmup", a->warmup, "untimed frames per cell")->capture_default_str();
  c->add_option("--modes", a->modes, "comma-separated subset of raymarch,shadow,pathtrace")->capture_default_str();
  c->add_option("--strategies", a->strategies,
                "comma-separated subset of inshader,streaming,cache (cache: the model's warm brick cache; default: "
                "all three for a model, inshader,streaming for a volume)");
  c->add_option("--with-macrocells", a->macrocells,
                "the 'with' setting: grid or online (default: online for a vnr-trained model, else grid)");
  c->add_option("--tune-k", a->tune_k,
                "instead of the table: streaming ray-marching frames/s for each K in this list (e.g. 1,2,4,8,16,32)");
  c->add_option("--report", a->report, "write a JSON report");
  a->r.add(c);
  a->vol.add(c);
  c->callback([a]() {
    set_num_threads(a->r.threads);
    if (a->frames < 1 || a->warmup < 0) fail("--frames must be at least 1 and --warmup at least 0");
    CliRender cr = open_cli_render(a->input, a->r, a->vol);
    Renderer& r = *cr.renderer;
    const RenderOptions options = r.options();
    const Model* model = r.model();
    const Volume* volume = cr.input->volume ? &*cr.input->volume : nullptr;
    MacroCellMode with =
        a->macrocells.empty() ? default_macrocell_mode(model, volume) : parse_macrocell_mode(a->macrocells);
    if (with == MacroCellMode::Off) with = volume ? MacroCellMode::Grid : MacroCellMode::Off;
    if (with == MacroCellMode::Off)
      fail("no macro-cells to compare with: give a model trained by vnr (online ranges) or --volume");
    r.set_macrocells(with, a->r.s.macrocell_size);
    BrickCacheSettings cache = r.cache().value_or(BrickCacheSettings{});  // --cache-budget, --cache-dims
    cache.budget_bytes = a->r.s.cache_budget;
    r.set_cache(std::nullopt);  // the cells choose; the raw rate is the model's own field
    r.prepare();  // a setting that cannot be rendered fails before the table starts

    // The raw rate: the CPU's batched query, or on the GPU the network's resident encoding + MLP (what
    // `vnr bench infer --device cuda` reports as resident); 0 = not measured (the grid on the GPU).
    const double raw = field_query_rate(r, 2.0);
    const RenderOrbit orbit{a->frames, a->warmup, cr.orbit_elevation, a->r.s.fovy, a->r.s.macrocell_size};

    Json report;
    report["input"] = cr.input->description;
    report["field"] = r.field_kind();
    report["size"] = {options.width, options.height};
    report["threads"] = num_threads();
    report["device"] = device_name(r.device());
    if (r.device() == Device::Cuda) report["gpu"] = cuda::devices().at(0).name;
    report["raw_field_samples_per_second"] = raw;
    const Json precision = precision_json(model, r.device());
    report["precision"] = precision;
    const std::string where =
        r.device() == Device::Cuda
            ? cuda::devices().at(0).name
            : fmt::format("{} threads{}", num_threads(),
                          precision.is_null() ? "" : fmt::format(", {} network", precision.get<std::string>()));
    std::printf("%s (%s field), %dx%d, %s; raw batched field query: %s\n\n", cr.input->description.c_str(),
                r.field_kind(), options.width, options.height, where.c_str(),
                raw > 0 ? fmt::format("{:.2f} M samples/s", raw / 1e6).c_str() : "not measured");

    if (!a->tune_k.empty()) {
      report["tune_k"] = tune_k_rows(r, with, orbit, split_list(a->tune_k));
    } else {
      const std::string strategies =
          !a->strategies.empty() ? a->strategies
                                 : (model ? (r.can_render_inshader() ? "inshader,streaming,cache" : "streaming,cache")
                                          : "inshader,streaming");
      report["rows"] = table_rows(r, with, orbit, cache, raw, split_list(a->modes), split_list(strategies));
    }
    write_report(a->report, report);
  });
}

}  // namespace vnr::cli
