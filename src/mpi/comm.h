#pragma once
// The MPI layer's process-wide state and collectives (Open MPI or any MPI-3 library). vnr starts MPI
// only when a launcher started it (mpirun, mpiexec, srun with PMI/PMIx): a plain `vnr` never touches
// MPI. Every collective here is called by all ranks in the same order; work that can fail runs
// inside agree(), so that a rank that throws makes every rank throw the same RankFailure instead of
// leaving the others waiting in the next collective.
#include <cstdint>
#include <functional>
#include <string>
#include <vector>
#include "vnr/error.h"

namespace vnr::mpi {

// True when an MPI launcher started this process (Open MPI's OMPI_COMM_WORLD_SIZE, PMI_SIZE, PMIX_RANK).
bool launched_by_mpi();

// MPI_Init on construction (thread level FUNNELED: OpenMP threads never call MPI), MPI_Finalize on
// destruction; one per process, made by main() when launched_by_mpi().
class Session {
public:
  Session(int* argc, char*** argv);
  ~Session();
  Session(const Session&) = delete;
  Session& operator=(const Session&) = delete;
};

// Fails with MPI's own text of rc unless it is MPI_SUCCESS; `what` names the call.
void check_mpi(int rc, const char* what);

// Whether a Session is live; rank 0 of 1 when none is.
bool active();
int rank();
int size();
// The processes of this rank's node (Open MPI's OMPI_COMM_WORLD_LOCAL_SIZE; 1 when unknown), and this
// rank's index among them (OMPI_COMM_WORLD_LOCAL_RANK, MPICH's MPI_LOCALRANKID or Slurm's SLURM_LOCALID;
// 0 when unknown).
int local_size();
int local_rank();

// Every rank failed or saw another fail: the message names the first failing rank, its brick when
// the work said which, and how many ranks failed. Every rank throws the same one.
class RankFailure : public Error {
public:
  explicit RankFailure(const std::string& msg) : Error(msg) {}
};

// Runs work on this rank, then all ranks learn whether any threw; if one did every rank throws
// RankFailure "rank R of N failed <phase>: <its message>" (+ " (K other ranks failed too)"), or "all N
// ranks failed <phase>: <rank 0's message>" when every rank did.
void agree(const std::string& phase, const std::function<void()>& work);

void barrier();
double sum(double v);
int64_t sum(int64_t v);
double max(double v);
// root's string on every rank.
std::string broadcast(const std::string& s, int root = 0);
// Every rank's string on root (indexed by rank); empty elsewhere.
std::vector<std::string> gather(const std::string& s, int root = 0);
// Every rank's value of v, indexed by rank.
std::vector<int64_t> all_gather(int64_t v);

// Ends every rank at once: the last resort for an error outside agree() (e.g. a rank killed during a
// collective leaves nothing to agree with).
[[noreturn]] void abort_all(int code);

}  // namespace vnr::mpi
