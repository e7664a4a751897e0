#pragma once
// The CLI's MPI entry (docs/MPI.md). Built with VNR_MPI and started by an MPI launcher (mpirun, mpiexec,
// srun), `vnr train|decode|eval|render` of multi-brick models run distributed over the ranks (cmd_mpi*.cpp);
// every other command refuses to run on more than one rank. Otherwise MpiCli does nothing.
#include <memory>
#include <string>
#include <CLI/CLI.hpp>
#include "vnr/error.h"

namespace vnr::cli {

// An error every rank throws alike (a refused command, a bad argument checked before any rank works).
class AllRanksError : public Error {
public:
  explicit AllRanksError(const std::string& msg) : Error(msg) {}
};

class MpiCli {
public:
  // Starts MPI when launched by an MPI launcher and swaps the distributed commands into app.
  MpiCli(int* argc, char*** argv, CLI::App& app);
  ~MpiCli();  // MPI_Finalize
  MpiCli(const MpiCli&) = delete;
  MpiCli& operator=(const MpiCli&) = delete;

  // "vnr: error: MSG" on stderr; returns the exit status. Distributed, only rank 0 prints an error every
  // rank has (agreed) and exits with `status` (the others with 0, so that mpirun reports one failure and
  // kills no rank still finalising); any other error is printed with its rank and ends the whole job,
  // since other ranks may be waiting for it.
  int print_error(const std::string& msg, bool agreed, int status) const;
  // Whether every rank threw e alike (RankFailure from the MPI layer, or AllRanksError).
  bool agreed(const Error& e) const;

private:
  struct State;
  std::unique_ptr<State> state_;
};

#ifdef VNR_HAVE_MPI
// The distributed commands (cmd_mpi_*.cpp), replacing the one-process ones under mpirun.
void add_train_mpi(CLI::App& app);
void add_decode_mpi(CLI::App& app);
void add_eval_mpi(CLI::App& app);
void add_render_mpi(CLI::App& app);
// CPU threads of a rank: --threads, else the node's cores shared by its ranks.
int rank_threads(int requested);
#endif

}  // namespace vnr::cli
