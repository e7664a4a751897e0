// `mpirun -n N vnr train VOLUME -o MODEL --bricks ...`: each rank trains the bricks assign_bricks gives
// it (balanced by voxels; each read from its own region of the volume), rank 0 writes the manifest.
// A brick's seed comes from the brick, so 1, 2 or N ranks train the same model.
#ifdef VNR_HAVE_MPI
#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include "mpi/comm.h"
#include "cli.h"
#include "mpi_cli.h"
#include "train_options.h"
#include "vnr/bricks.h"
#include "vnr/fileio.h"
#include "vnr/threads.h"
#include "vnr/units.h"

namespace vnr::cli {

namespace {

// The setup `vnr train` builds (setup_of), checked, with the bricks' refusals; the fill bars of
// out-of-core bricks stay off (ranks would interleave them).
TrainingSetup mpi_setup_of(const TrainArgs& a) {
  check_brick_args(a);
  TrainingSetup s = setup_of(a, false);
  s.data.show_progress = false;
  check_training_setup(s);
  return s;
}

std::string describe_box(const Box3& b) {
  return fmt::format("x {}..{}, y {}..{}, z {}..{}", b.lo.x, b.hi.x, b.lo.y, b.hi.y, b.lo.z, b.hi.z);
}

// This rank's bricks, trained one after another; a failure names the brick.
std::vector<BrickResult> train_my_bricks(const TrainingSetup& setup, const BrickPlan& plan, const std::vector<int>& mine,
                                         const ValueRange& range, const TrainArgs& a) {
  std::vector<BrickResult> results;
  for (size_t k = 0; k < mine.size(); ++k) {
    const int b = mine[k];
    // Which brick a rank was on is what a killed rank's user needs: mpirun names only the rank.
    if (!a.quiet)
      std::fprintf(stderr, "rank %d: training brick %d (%zu of %zu on this rank)\n", mpi::rank(), b, k + 1, mine.size());
    BrickTrainOptions o;
    o.steps = brick_steps(a);
    o.seconds = a.seconds;
    o.message = [&](const std::string& line) {  // notes, e.g. that the brick trains out of core and why
      if (!a.quiet && line.rfind("note:", 0) == 0) std::fprintf(stderr, "rank %d: %s\n", mpi::rank(), line.c_str());
    };
    try {
      results.push_back(train_brick(setup, plan, b, a.s.session.output, range, o));
    } catch (const std::exception& e) {
      fail("brick {} ({}): {}", b, describe_box(plan.bricks[size_t(b)].owned), e.what());
    }
    const BrickResult& r = results.back();
    if (!a.quiet)
      std::fprintf(stderr, "rank %d: brick %d trained: %lld steps in %.1fs, PSNR %.2f dB on its region\n", mpi::rank(), b,
                   (long long)r.steps, r.seconds, r.psnr);
  }
  return results;
}

std::string config_text(const TrainingSetup& s) { return s.config_json ? s.config_json->dump() : s.config; }

// The manifest as `vnr train --bricks` writes it (train/bricks_run.cpp), from the brick files on disk:
// before training (complete: false, so that --resume finds the plan) and after.
void write_manifest_now(const TrainArgs& a, const TrainingSetup& setup, const BrickPlan& plan, DType dtype,
                        const ValueRange& range, bool final) {
  const std::vector<bool> done = bricks_done(a.s.session.output, plan, config_text(setup));
  const std::vector<BrickResult> all = brick_results_on_disk(a.s.session.output, plan, done);
  const Json config = setup.config_json ? *setup.config_json : Json(setup.config);
  if (!final) return write_manifest(a.s.session.output, plan, dtype, range, config, all);
  Json training = bricks_training_summary(setup, plan, all, brick_steps(a));
  training["ranks"] = mpi::size();
  write_manifest(a.s.session.output, plan, dtype, range, config, all, training);
}

void run_train_mpi(const TrainArgs& a) {
  const int me = mpi::rank(), n = mpi::size();
  TrainingSetup setup;
  BrickPlan plan;
  DType dtype = DType::Float32;
  mpi::agree("to plan the bricks", [&] {
    setup = mpi_setup_of(a);
    // A node's ranks spread over its GPUs (each rank's bricks train on its own).
    if (cuda::resolve_device(setup.device) == Device::Cuda) cuda::use_device_for(mpi::local_rank());
    const VolumeDesc desc = describe_volume(a.s.volume, setup.raw);
    dtype = desc.dtype;
    plan = plan_bricks(desc.dims, parse_brick_grid(a.bricks), a.ghost, a.s.seed);
  });
  // Rank 0 prepares the directory, finds the value range (sidecar, else one scan: every brick normalises
  // with it) and which bricks are done, and writes the first manifest; the others learn range and bricks.
  ValueRange range;
  std::string done_bits(plan.bricks.size(), '0');
  mpi::agree("to prepare the model directory", [&] {
    if (me != 0) return;
    prepare_brick_dir(a.s.session.output, plan, a.resume);
    range = brick_value_range(setup, [&](const std::string& m) { if (!a.quiet) std::fprintf(stderr, "%s\n", m.c_str()); });
    const std::vector<bool> done = bricks_done(a.s.session.output, plan, config_text(setup));
    for (size_t i = 0; i < done.size(); ++i) done_bits[i] = done[i] ? '1' : '0';
    write_manifest_now(a, setup, plan, dtype, range, false);
  });
  const std::string bytes = mpi::broadcast(std::string(reinterpret_cast<const char*>(&range), sizeof range));
  std::memcpy(&range, bytes.data(), sizeof range);
  done_bits = mpi::broadcast(done_bits);
  std::vector<int> mine;
  const std::vector<std::vector<int>> assignment = assign_bricks(plan, n);
  for (int b : assignment[size_t(me)])
    if (done_bits[size_t(b)] == '0') mine.push_back(b);
  if (me == 0 && !a.quiet)
    std::fprintf(stderr, "training %zu bricks (%d already done) of %lldx%lldx%lld on %d ranks\n", plan.bricks.size(),
                 int(std::count(done_bits.begin(), done_bits.end(), '1')), (long long)plan.dims.x,
                 (long long)plan.dims.y, (long long)plan.dims.z, n);
  std::vector<BrickResult> results;
  mpi::agree("training", [&] { results = train_my_bricks(setup, plan, mine, range, a); });
  double longest = 0;
  for (const BrickResult& r : results) longest = std::max(longest, r.seconds);
  longest = mpi::max(longest);
  mpi::agree("to write the manifest", [&] {
    if (me != 0) return;
    write_manifest_now(a, setup, plan, dtype, range, true);
    std::printf("trained %zu bricks on %d ranks into %s (longest brick %.1fs)\n", plan.bricks.size(), n,
                a.s.session.output.c_str(), longest);
    write_report(a.report, Json{{"model", a.s.session.output}, {"ranks", n}, {"bricks", plan.bricks.size()},
                                {"grid", {plan.grid.x, plan.grid.y, plan.grid.z}}, {"ghost", plan.ghost}});
  });
}

}  // namespace

void add_train_mpi(CLI::App& app) {
  auto a = std::make_shared<TrainArgs>();
  a->bricks = "auto";
  CLI::App* c = app.add_subcommand("train", "train a multi-brick model, each rank its bricks (under mpirun; docs/MPI.md)");
  c->add_option("volume", a->s.volume, "volume (sidecar, NRRD or raw with --dims --dtype; uncompressed)")->required();
  c->add_option("-o,--output", a->s.session.output, "model directory (manifest.json + one .vnr per brick)")->required();
  // The options of `vnr train` (train_options.h): --steps and --seconds apply per brick, --memory-budget
  // per rank (a brick over it trains out of core), --threads per rank (default: the node's cores / its ranks).
  add_training_options(c, *a);
  c->callback([a] {
    set_num_threads(rank_threads(a->threads));
    run_train_mpi(*a);
  });
}

}  // namespace vnr::cli
#endif
