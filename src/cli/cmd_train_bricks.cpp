// `vnr train VOLUME --bricks BX,BY,BZ|auto [--ghost G] [--resume] -o DIR`: a multi-brick model trained
// brick by brick in this process (train/bricks.h; the MPI layer trains the same bricks across ranks).
#include <atomic>
#include <cstdio>
#include <optional>
#include "train_cli.h"
#include "train_options.h"
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/threads.h"
#include "vnr/progress.h"
#include "vnr/units.h"
#include "vnr/model.h"
#include "vnr/bricks.h"

namespace vnr::cli {

namespace {

// Ctrl-C stops the current brick after its step (its file is kept, marked incomplete) and no other
// brick starts; a second signal exits at once. --resume continues.
std::atomic<bool> g_stop_bricks{false};
extern "C" void on_stop_bricks(int) {
  g_stop_bricks.store(true);
  handle_stop_signals(exit_on_signal);
}

void print_summary(const TrainArgs& a, const BricksRunResult& r) {
  const Model m = load_model(a.s.session.output);
  const uint64_t bytes = model_file_bytes(a.s.session.output);
  std::printf("%zu bricks (%lldx%lldx%lld, ghost %d): %d trained now, %d already done\n", r.plan.bricks.size(),
              (long long)r.plan.grid.x, (long long)r.plan.grid.y, (long long)r.plan.grid.z, r.plan.ghost,
              int(r.trained.size()), r.already_done);
  FileEvalOptions o;
  o.with_ssim = !a.no_ssim;
  o.open = a.vol.open();
  o.model_path = a.s.session.output;
  if (!a.memory_budget.empty()) o.memory_budget = parse_byte_size(a.memory_budget);
  const FileEvaluation ev = evaluate_model_file(m, a.s.volume, o);
  std::printf("PSNR %.2f dB over the whole volume", ev.psnr);
  if (ev.ssim) std::printf(", SSIM %.4f", *ev.ssim);
  std::printf(", max |error| %.4g (%.4g in data units)\n", ev.max_abs_error, ev.max_abs_error_original);
  std::printf("model %s: %s in %zu files, %llu parameters; compression ratio %s\n", a.s.session.output.c_str(),
              human_bytes(double(bytes)).c_str(), r.plan.bricks.size() + 1,
              (unsigned long long)m.n_params(), format_ratio(ev.compression_ratio).c_str());
  Json report = {{"model", a.s.session.output},          {"bricks", r.plan.bricks.size()},   {"grid", {r.plan.grid.x, r.plan.grid.y, r.plan.grid.z}},
                 {"ghost", r.plan.ghost},      {"trained_now", r.trained.size()}, {"already_done", r.already_done},
                 {"psnr", ev.psnr},            {"max_abs_error", ev.max_abs_error}, {"model_bytes", bytes},
                 {"compression_ratio", ev.compression_ratio}, {"seconds", r.seconds}};
  if (ev.ssim) report["ssim"] = *ev.ssim;
  write_report(a.report, report);
}

}  // namespace

void print_brick_info(const Json& j) {
  const Json& b = j["bricks"];
  std::printf("bricks: %zu (%lldx%lldx%lld), ghost %d voxels, seed %u; per brick (index, owned lo..hi, parameters, "
              "PSNR on its region):\n",
              b["count"].get<size_t>(), b["grid"][0].get<long long>(), b["grid"][1].get<long long>(),
              b["grid"][2].get<long long>(), b["ghost"].get<int>(), b["seed"].get<uint32_t>());
  for (const Json& e : b["list"])
    std::printf("  %d: [%s..%s) %llu params, %.2f dB\n", e["index"].get<int>(), e["owned"]["lo"].dump().c_str(),
                e["owned"]["hi"].dump().c_str(), (unsigned long long)e["n_params"].get<uint64_t>(), e["psnr"].get<double>());
}

void add_train_bricks_options(CLI::App* c, TrainArgs& a) {
  c->add_option("--bricks", a.bricks,
                "train a multi-brick model: BX,BY,BZ bricks, or auto (bricks of at most 256^3 voxels); -o is then a "
                "directory (docs/MODEL_FORMAT.md)");
  c->add_option("--ghost", a.ghost, "with --bricks: voxels of overlap each brick also learns, blended across faces")
      ->capture_default_str();
  c->add_flag("--resume", a.resume,
              "with --bricks: keep the bricks already trained in -o DIR and train only the missing or damaged ones");
}

void run_train_bricks(const TrainArgs& a) {
  check_brick_args(a);
  TrainingSetup setup = setup_of(a, false);
  if (a.eval_samples < 0) fail("--eval-samples must be non-negative, got {}", a.eval_samples);
  const Int3 grid = parse_brick_grid(a.bricks);
  BricksRunOptions o;
  o.resume = a.resume;
  o.brick.steps = brick_steps(a);  // --steps and --seconds apply per brick
  o.brick.seconds = a.seconds;
  const bool by_time = o.brick.steps < 0;
  o.brick.with_ssim = false;
  o.brick.stop = &g_stop_bricks;
  std::optional<Progress> bar;
  o.brick.message = [&](const std::string& line) {
    if (!a.quiet && line.rfind("note:", 0) == 0) std::fprintf(stderr, "%s\n", line.c_str());
  };
  o.on_brick_start = [&](const BrickSpec& b, int k, int n) {
    bar.emplace(fmt::format("brick {} ({}/{})", b.index, k + 1, n), by_time ? a.seconds : double(o.brick.steps), a.quiet);
  };
  o.brick.on_step = [&](const TrainingProgress& p) {
    bar->update(by_time ? p.elapsed : double(p.step), fmt::format("step {} loss {:.5f}", p.step, p.loss));
  };
  o.on_brick_done = [&](const BrickResult& r) {
    bar->finish(fmt::format("({} steps, loss {:.5f}, PSNR {:.2f} dB on its region)", r.steps, r.final_loss, r.psnr));
  };
  set_num_threads(a.threads);
  BricksRunResult r;
  {
    g_stop_bricks.store(false);
    StopSignalScope signals(on_stop_bricks);
    r = train_bricks(setup, grid, a.ghost, a.s.session.output, o);
  }
  if (!r.complete) {
    fail("interrupted: {} of {} bricks are done in '{}'; run the same command with --resume to train the rest",
         r.done, r.plan.bricks.size(), a.s.session.output);
  }
  print_summary(a, r);
}

}  // namespace vnr::cli
