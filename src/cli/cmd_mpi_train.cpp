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
#include "vnr/bricks.h"
#include "vnr/core/fileio.h"
#include "vnr/core/parallel.h"
#include "vnr/core/units.h"

namespace vnr::cli {

namespace {

struct TrainMpiArgs {
  std::string volume, output, bricks = "auto", config = "paper", report, memory_budget, device = "auto";
  int ghost = 4, threads = 0;
  int64_t steps = 1000, batch = 65536;
  double seconds = 0, target_ratio = 0;
  uint32_t seed = 1337;
  bool resume = false, quiet = false;
  VolumeArgs vol;
};

TrainingSetup setup_of(const TrainMpiArgs& a) {
  TrainingSetup s;
  s.volume = a.volume;
  s.raw = a.vol.raw();
  s.load = a.vol.load();
  s.config = a.config;
  s.target_ratio = a.target_ratio;
  s.batch = a.batch;
  s.seed = a.seed;
  s.device = a.device;
  s.steps = a.steps;
  if (!a.memory_budget.empty()) s.data.memory_budget = parse_byte_size(a.memory_budget);
  check_training_setup(s);
  return s;
}

std::string describe_box(const Box3& b) {
  return fmt::format("x {}..{}, y {}..{}, z {}..{}", b.lo.x, b.hi.x, b.lo.y, b.hi.y, b.lo.z, b.hi.z);
}

// This rank's bricks, trained one after another; a failure names the brick.
std::vector<BrickResult> train_my_bricks(const TrainingSetup& setup, const BrickPlan& plan, const std::vector<int>& mine,
                                         const ValueRange& range, const TrainMpiArgs& a) {
  std::vector<BrickResult> results;
  for (size_t k = 0; k < mine.size(); ++k) {
    const int b = mine[k];
    // Which brick a rank was on is what a killed rank's user needs: mpirun names only the rank.
    if (!a.quiet)
      std::fprintf(stderr, "rank %d: training brick %d (%zu of %zu on this rank)\n", mpi::rank(), b, k + 1, mine.size());
    BrickTrainOptions o;
    o.steps = a.steps;
    o.seconds = a.seconds;
    try {
      results.push_back(train_brick(setup, plan, b, a.output, range, o));
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
void write_manifest_now(const TrainMpiArgs& a, const TrainingSetup& setup, const BrickPlan& plan, DType dtype,
                        const ValueRange& range, bool final) {
  const std::vector<bool> done = bricks_done(a.output, plan, config_text(setup));
  const std::vector<BrickResult> all = brick_results_on_disk(a.output, plan, done);
  const Json config = setup.config_json ? *setup.config_json : Json(setup.config);
  if (!final) return write_manifest(a.output, plan, dtype, range, config, all);
  int64_t steps = 0;
  double seconds = 0;
  for (const BrickResult& b : all) steps += b.steps, seconds += b.seconds;
  const Json training = {{"bricks_done", all.size()}, {"bricks", plan.bricks.size()},
                         {"complete", all.size() == plan.bricks.size()}, {"steps_per_brick", a.steps},
                         {"brick_steps", steps}, {"brick_seconds", seconds}, {"batch", setup.batch},
                         {"seed", setup.seed}, {"target_ratio", setup.target_ratio}, {"ranks", mpi::size()}};
  write_manifest(a.output, plan, dtype, range, config, all, training);
}

void run_train_mpi(const TrainMpiArgs& a) {
  const int me = mpi::rank(), n = mpi::size();
  TrainingSetup setup;
  BrickPlan plan;
  DType dtype = DType::Float32;
  mpi::agree("to plan the bricks", [&] {
    setup = setup_of(a);
    const VolumeDesc desc = describe_volume(a.volume, setup.raw);
    dtype = desc.dtype;
    plan = plan_bricks(desc.dims, parse_brick_grid(a.bricks), a.ghost, a.seed);
  });
  // Rank 0 prepares the directory, finds the value range (sidecar, else one scan: every brick normalises
  // with it) and which bricks are done, and writes the first manifest; the others learn range and bricks.
  ValueRange range;
  std::string done_bits(plan.bricks.size(), '0');
  mpi::agree("to prepare the model directory", [&] {
    if (me != 0) return;
    prepare_brick_dir(a.output, plan, a.resume);
    range = brick_value_range(setup, [&](const std::string& m) { if (!a.quiet) std::fprintf(stderr, "%s\n", m.c_str()); });
    const std::vector<bool> done = bricks_done(a.output, plan, config_text(setup));
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
                a.output.c_str(), longest);
    write_report(a.report, Json{{"model", a.output}, {"ranks", n}, {"bricks", plan.bricks.size()},
                                {"grid", {plan.grid.x, plan.grid.y, plan.grid.z}}, {"ghost", plan.ghost}});
  });
}

}  // namespace

void add_train_mpi(CLI::App& app) {
  auto a = std::make_shared<TrainMpiArgs>();
  CLI::App* c = app.add_subcommand("train", "train a multi-brick model, each rank its bricks (under mpirun; docs/MPI.md)");
  c->add_option("volume", a->volume, "volume (sidecar, NRRD or raw with --dims --dtype; uncompressed)")->required();
  c->add_option("-o,--output", a->output, "model directory (manifest.json + one .vnr per brick)")->required();
  c->add_option("--bricks", a->bricks, "bricks per axis BX,BY,BZ or auto")->capture_default_str();
  c->add_option("--ghost", a->ghost, "ghost voxels on each side of a brick")->capture_default_str();
  c->add_flag("--resume", a->resume, "train only the bricks not yet in the model directory");
  c->add_option("--config", a->config, "preset (paper, small) or tiny-cuda-nn JSON config file")->capture_default_str();
  c->add_option("--target-ratio", a->target_ratio, "size every brick so the whole model is about 1/R of the volume");
  c->add_option("--steps", a->steps, "training steps per brick")->capture_default_str();
  c->add_option("--seconds", a->seconds, "stop each brick after this many seconds");
  c->add_option("--batch", a->batch, "samples per step (multiple of 256)")->capture_default_str();
  c->add_option("--seed", a->seed, "seed of the model (each brick's seed derives from it and the brick)")->capture_default_str();
  c->add_option("--memory-budget", a->memory_budget, "memory a rank may use for one brick's data, e.g. 4GiB");
  c->add_option("--threads", a->threads, "CPU threads per rank (default: the node's cores / its ranks)");
  c->add_option("--report", a->report, "write a JSON report (rank 0)");
  c->add_flag("-q,--quiet", a->quiet, "no progress output");
  add_device_option(c, a->device);
  a->vol.add(c);
  c->callback([a] {
    set_num_threads(rank_threads(a->threads));
    run_train_mpi(*a);
  });
}

}  // namespace vnr::cli
#endif
