// The options of one training run shared by `vnr train` and `mpirun vnr train` (train_options.h), and the
// TrainingSetup both build from them.
#include "train_options.h"
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/units.h"
#include "vnr/model.h"

namespace vnr::cli {

TrainingSetup setup_of(const TrainArgs& a, bool preview) {
  TrainingSetup s = a.s;
  s.raw = a.vol.raw();
  s.load = a.vol.load();
  if (preview) s.cpu_only_reason = "--preview-* options run on the CPU trainer";
  if (!a.block_dims.empty()) s.data.block_dims = parse_dims(a.block_dims);
  s.data.show_progress = !a.quiet;
  if (!a.memory_budget.empty() && (s.data.memory_budget = parse_byte_size(a.memory_budget)) == 0)
    fail("--memory-budget must be positive");
  return s;
}

int64_t brick_steps(const TrainArgs& a) { return planned_steps(a.s.steps, a.seconds); }

void check_brick_args(const TrainArgs& a) {
  if (a.bricks.empty()) fail("--resume needs --bricks (the same as the run it continues)");
  if (a.preview.enabled()) fail("--preview-* options are not supported with --bricks");
  if (a.s.session.checkpoint_every) fail("--checkpoint-every is not supported with --bricks (each finished brick is kept; --resume continues)");
  if (a.s.session.error_bound.active())
    fail("--max-error/--max-rel-error are not supported with --bricks yet (residuals are per single model)");
  if (a.s.target_psnr > 0) fail("--target-psnr is not supported with --bricks yet; give --target-ratio or a config");
  if (is_instantvnr_path(a.s.session.output) || extension_of(a.s.session.output) == ".vnr")
    fail("with --bricks, -o names a directory (the manifest and one .vnr per brick), got '{}'", a.s.session.output);
}

void add_training_options(CLI::App* c, TrainArgs& a) {
  c->add_option("--config", a.s.config,
                "auto (the paper's network; with --max-error/--max-rel-error alone, sized for the bound), a preset "
                "(paper, small) or a tiny-cuda-nn JSON config file")
      ->capture_default_str();
  c->add_option("--max-error", a.s.session.error_bound.max_error,
                 "guarantee |decoded - original| <= E (data units) at every voxel: quantised residuals of the "
                 "network are stored in the model (docs/COMPRESSION.md)");
  c->add_option("--max-rel-error", a.s.session.error_bound.max_rel_error, "the same bound as a fraction of the value range, e.g. 1e-3");
  c->add_option("--target-ratio", a.s.target_ratio,
                 "write a compact (quantized, entropy-coded) model of volume bytes / R, within 5 %");
  c->add_option("--target-psnr", a.s.target_psnr,
                 "the smallest compact model reaching this PSNR (dB, held-back voxels): bisection over sizes "
                 "1/1024..1/4 of the volume, each trained --steps/--seconds; with --target-ratio, one model of "
                 "that size quantized as coarsely as keeps the PSNR");
  c->add_option("--residuals", a.s.residuals,
                 "--target-ratio alone: auto spends part of the file on residuals (the finest error bound that "
                 "fits beside a smaller network) where that decodes better, off keeps the whole file for the network; "
                 "rendering uses the network alone (docs/COMPRESSION.md)")
      ->capture_default_str()
      ->check(CLI::IsMember({"auto", "off"}));
  c->add_option("--bits-per-param", a.s.bits_per_param,
                 "--target-ratio: size the hash grid for this many bits per parameter after coding")
      ->capture_default_str();
  c->add_option("--qat-fraction", a.s.qat_fraction,
                 "compact models: the last part of the steps trained on quantized parameters")
      ->capture_default_str();
  c->add_option("--rate-weight", a.s.rate_weight,
                 "compact models: weight of the grid's bits in the loss over the quantization-aware steps "
                 "(rate-aware training; 0: distortion alone)")
      ->capture_default_str();
  c->add_flag("--learn-steps", a.s.learn_steps,
              "compact models: train each grid level's quantization step over the quantization-aware steps, the bits' "
              "weight following the byte budget (CPU trainer)");
  c->add_option("--steps", a.s.steps, "training steps (default 1000, or unlimited with --seconds)");
  c->add_option("--cooldown", a.s.session.cooldown,
                "last fraction of --steps/--seconds over which the learning rate falls linearly to 0 (0: tcnn's "
                "schedule exactly)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1.0));
  c->add_option("--seconds", a.seconds, "stop after this many seconds of training");
  c->add_option("--batch", a.s.batch, "samples per step (multiple of 256)")->capture_default_str();
  c->add_option("--seed", a.s.seed, "seed for initialisation and sampling")->capture_default_str();
  c->add_option("--threads", a.threads, "CPU threads (default: all cores)");
  add_device_option(c, a.s.device);
  c->add_option("--mlp", a.s.mlp, "cuda: MLP implementation, auto (fused when the width allows), fused or cublas")
      ->check(CLI::IsMember({"auto", "fused", "cublas"}))
      ->capture_default_str();
  add_training_precision_option(c, a.s.precision);
  c->add_option("--report", a.report, "write a JSON report");
  c->add_option("--macrocell-size", a.s.macrocell_size,
                 "voxels per macro-cell of the value ranges recorded from the training samples for rendering (0: none)")
      ->capture_default_str();
  c->add_option("--sampler", a.s.data.sampler,
                 "where training samples come from: incore (volume in memory), outofcore (random block buffer "
                 "refreshed by background reads), mmap (memory-mapped file; the paper's baseline). Default: incore "
                 "when the volume fits the memory budget, else outofcore")
      ->check(CLI::IsMember({"incore", "outofcore", "mmap"}));
  c->add_option("--memory-budget", a.memory_budget,
                "memory for the training data, e.g. 16MiB, 2GiB (default: half of the available memory)");
  c->add_option("--blocks", a.s.data.blocks, "outofcore: blocks in the buffer (default 65536, scaled down to the budget)");
  c->add_option("--refresh", a.s.data.refresh, "outofcore: blocks replaced per step (default blocks/4, at most 1024; the paper used 1024 of 65536)");
  c->add_option("--grid-lr-scale", a.s.data.grid_lr_scale,
                "outofcore: factor on the hash grid's learning rate, or auto = the fraction of the volume in the "
                "buffer (at least 0.1); try auto or 0.1-0.3 when the loss spikes (see README)")
      ->capture_default_str();
  c->add_option("--block-dims", a.block_dims,
                "outofcore: interior voxels of a block X,Y,Z (default 256 along x, y = z for about 64 KiB of data)");
  c->add_flag("-q,--quiet", a.quiet, "no progress output");
  a.vol.add(c);
  add_train_bricks_options(c, a);
}

}  // namespace vnr::cli
