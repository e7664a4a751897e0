// MpiCli: MPI start-up, the distributed commands swapped in, errors printed once per job.
#include <algorithm>
#include <cstdio>
#include <iterator>
#include <optional>
#include <thread>
#include "mpi_cli.h"
#ifdef VNR_HAVE_MPI
#include "mpi/comm.h"
#endif

namespace vnr::cli {

#ifdef VNR_HAVE_MPI
struct MpiCli::State {
  std::optional<mpi::Session> session;
};

namespace {
constexpr const char* kDistributed[] = {"train", "decode", "eval", "render"};
bool is_distributed_command(const std::string& name) {
  return std::find(std::begin(kDistributed), std::end(kDistributed), name) != std::end(kDistributed);
}
}  // namespace

// Replaces the one-process train, decode, eval and render by their distributed forms.
void add_distributed_commands(CLI::App& app) {
  for (const std::string name : kDistributed)
    for (CLI::App* sub : app.get_subcommands({}))
      if (sub->get_name() == name) {
        app.remove_subcommand(sub);
        break;
      }
  add_train_mpi(app);
  add_decode_mpi(app);
  add_eval_mpi(app);
  add_render_mpi(app);
}

int rank_threads(int requested) {
  if (requested > 0) return requested;
  const int cores = int(std::thread::hardware_concurrency());
  return std::max(1, cores / mpi::local_size());
}

MpiCli::MpiCli(int* argc, char*** argv, CLI::App& app) : state_(std::make_unique<State>()) {
  if (!mpi::launched_by_mpi()) return;
  state_->session.emplace(argc, argv);
  add_distributed_commands(app);
  if (mpi::size() == 1) return;
  for (CLI::App* sub : app.get_subcommands({})) {
    const std::string name = sub->get_name();
    if (is_distributed_command(name)) continue;
    sub->callback([name] {
      throw AllRanksError(fmt::format("'vnr {}' runs in one process: start it without mpirun (train, decode, eval "
                                      "and render of multi-brick models run distributed)", name));
    });
  }
}

MpiCli::~MpiCli() = default;

bool MpiCli::agreed(const Error& e) const {
  return dynamic_cast<const mpi::RankFailure*>(&e) || dynamic_cast<const AllRanksError*>(&e);
}

int MpiCli::print_error(const std::string& msg, bool agreed, int status) const {
  if (!mpi::active() || mpi::size() == 1) {
    std::fprintf(stderr, "vnr: error: %s\n", msg.c_str());
    return status;
  }
  if (agreed) {
    if (mpi::rank() != 0) return 0;
    std::fprintf(stderr, "vnr: error: %s\n", msg.c_str());
    return status;
  }
  std::fprintf(stderr, "vnr: error: rank %d of %d: %s\n", mpi::rank(), mpi::size(), msg.c_str());
  std::fflush(stderr);
  mpi::abort_all(1);
}
#else
struct MpiCli::State {};
MpiCli::MpiCli(int*, char***, CLI::App&) {}
MpiCli::~MpiCli() = default;
bool MpiCli::agreed(const Error&) const { return true; }
int MpiCli::print_error(const std::string& msg, bool, int status) const {
  std::fprintf(stderr, "vnr: error: %s\n", msg.c_str());
  return status;
}
#endif

}  // namespace vnr::cli
