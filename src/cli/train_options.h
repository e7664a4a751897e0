#pragma once
// The options of one training run, shared by `vnr train` (cmd_train.cpp, cmd_train_bricks.cpp) and
// `mpirun vnr train` (cmd_mpi_train.cpp), so that both accept the same options and build the same
// TrainingSetup from them (setup_of, train_cli.h).
#include "train_cli.h"

namespace vnr::cli {

// Registers the training options both commands take: config and model size (--config, --target-ratio,
// --target-psnr, --bits-per-param, --qat-fraction, --max-error, --max-rel-error), the run (--steps,
// --seconds, --batch, --seed, --threads, --device, --mlp, --precision, --macrocell-size, --report, -q),
// the samplers and memory budget, the volume options and --bricks/--ghost/--resume.
void add_training_options(CLI::App* c, TrainArgs& a);
// Options that cannot apply per brick, each refused with one line (both commands). allow_seconds: the
// caller stops each brick after --seconds.
void check_brick_args(const TrainArgs& a);
// Steps of each brick as `vnr train` counts them: --steps, else 1000, or no limit (-1) with --seconds.
int64_t brick_steps(const TrainArgs& a);

}  // namespace vnr::cli
