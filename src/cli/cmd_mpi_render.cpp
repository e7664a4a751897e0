// `mpirun -n N vnr render MODEL_DIR -o IMAGE`: each rank renders the ray segments inside its bricks
// (render_brick_segment: premultiplied RGBA on the whole frame's sample grid), the images are composited
// sort-last by direct send in visibility order (src/mpi; for every ray the same order as its segments'
// first samples, which composite_brick_segments sorts by), and rank 0 puts the result over the
// background and writes it.
#ifdef VNR_HAVE_MPI
#include <chrono>
#include <cstdio>
#include "mpi/comm.h"
#include "mpi/sort_last.h"
#include "mpi_cli.h"
#include "render_setup.h"
#include "vnr/bricks.h"
#include "vnr/fileio.h"
#include "vnr/threads.h"

namespace vnr::cli {

namespace {
struct RenderMpiArgs {
  std::string input, output, report;
  bool quiet = false;
  RenderArgs r;
  VolumeArgs vol;
};

void run_render_mpi(const RenderMpiArgs& a) {
  CliRender cr;
  const BrickedModel* m = nullptr;
  mpi::agree("to open the model", [&] {
    const std::string ext = extension_of(a.output);
    if (ext != ".png" && ext != ".pfm") fail("-o must name a .png or .pfm file, got '{}'", a.output);
    if (!is_bricked_model_dir(a.input))
      fail("'{}' is not a multi-brick model directory: under mpirun, render draws the bricks of a model trained "
           "with --bricks; render anything else without mpirun", a.input);
    RenderArgs one = a.r;
    // Each rank draws its bricks' segments on the CPU (render_brick_segment); auto would take a GPU.
    if (one.s.device == "cuda")
      fail("under mpirun, render draws each rank's bricks on the CPU: leave --device out or give cpu");
    one.s.device = "cpu";
    one.s.spp = 1;  // one frame, each rank its bricks' networks
    cr = open_cli_render(a.input, one, a.vol);
    m = bricked(*cr.input->model);
    if (!m) fail("'{}' opened without its bricks", a.input);
  });
  Renderer& r = *cr.renderer;
  const auto t0 = std::chrono::steady_clock::now();
  const std::vector<int> mine = assign_bricks(m->plan, mpi::size())[size_t(mpi::rank())];
  std::vector<Image> images(mine.size());
  mpi::agree("rendering", [&] {
    r.prepare();
    for (size_t i = 0; i < mine.size(); ++i) images[i] = std::move(render_brick_segment(r, mine[i]).rgba);
  });
  const double render_seconds = mpi::max(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  std::vector<int> owner(m->plan.bricks.size());
  std::vector<mpi::Bounds3f> bounds;
  const std::vector<std::vector<int>> assignment = assign_bricks(m->plan, mpi::size());
  for (size_t rank = 0; rank < assignment.size(); ++rank)
    for (int b : assignment[rank]) owner[size_t(b)] = int(rank);
  for (const BrickSpec& b : m->plan.bricks)
    bounds.push_back({{float(b.owned.lo.x), float(b.owned.lo.y), float(b.owned.lo.z)},
                      {float(b.owned.hi.x), float(b.owned.hi.y), float(b.owned.hi.z)}});
  std::vector<mpi::BrickImage> parts;
  for (size_t i = 0; i < mine.size(); ++i) parts.push_back({mine[i], &images[i]});
  const RenderOptions& o = r.options();
  mpi::CompositeStats stats;
  Image img = mpi::composite_direct_send(parts, owner, mpi::visibility_order(bounds, r.camera().eye), o.width, o.height,
                                         &stats);
  const int64_t bytes = mpi::sum(stats.bytes_sent);
  mpi::agree("to write the image", [&] {
    if (mpi::rank() != 0) return;
    mpi::put_over_background(img, o.background);
    write_image(a.output, img);
  });
  if (mpi::rank() == 0 && !a.quiet)
    std::printf("rendered %zu bricks on %d ranks: %dx%d, %.3fs rendering, %.3fs compositing (%.1f MiB sent) -> %s\n",
                m->plan.bricks.size(), mpi::size(), o.width, o.height, render_seconds, stats.seconds,
                double(bytes) / (1 << 20), a.output.c_str());
  if (mpi::rank() == 0)
    write_report(a.report, Json{{"ranks", mpi::size()}, {"render_seconds", render_seconds},
                                {"composite_seconds", stats.seconds}, {"composite_bytes", bytes}});
}
}  // namespace

void add_render_mpi(CLI::App& app) {
  auto a = std::make_shared<RenderMpiArgs>();
  CLI::App* c = app.add_subcommand("render", "render a multi-brick model, each rank its bricks, composited sort-last (under mpirun)");
  c->add_option("input", a->input, "multi-brick model directory")->required();
  c->add_option("-o,--output", a->output, "image file: .png (8-bit) or .pfm (float)")->required();
  c->add_option("--report", a->report, "write a JSON report (rank 0)");
  c->add_flag("-q,--quiet", a->quiet, "no progress output");
  a->r.add(c);
  a->vol.add(c);
  c->callback([a] {
    set_num_threads(rank_threads(a->r.threads));
    run_render_mpi(*a);
  });
}

}  // namespace vnr::cli
#endif
