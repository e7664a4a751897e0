#include "mpi/comm.h"
#include <mpi.h>
#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <exception>
#include <new>
#include <string>

namespace vnr::mpi {

namespace {
bool g_active = false;
int g_rank = 0, g_size = 1;

bool env_set(const char* name) {
  const char* v = std::getenv(name);
  return v && *v;
}
}  // namespace

void check_mpi(int rc, const char* what) {
  if (rc == MPI_SUCCESS) return;
  char text[MPI_MAX_ERROR_STRING];
  int len = 0;
  MPI_Error_string(rc, text, &len);
  fail("MPI {} failed: {}", what, std::string(text, size_t(len)));
}

bool launched_by_mpi() {
  // A program that called MPI_Init without a launcher (an Open MPI "singleton", e.g. pvpython) passes
  // PMIX_RANK to its children; that is not a launch by mpirun, and vnr must run as one process there.
  const char* ess = std::getenv("OMPI_MCA_ess");
  if (ess && std::string(ess) == "singleton" && !env_set("OMPI_COMM_WORLD_SIZE")) return false;
  return env_set("OMPI_COMM_WORLD_SIZE") || env_set("PMI_SIZE") || env_set("PMIX_RANK");
}

Session::Session(int* argc, char*** argv) {
  if (g_active) fail("MPI is already initialised");
  int provided = 0;
  check_mpi(MPI_Init_thread(argc, argv, MPI_THREAD_FUNNELED, &provided), "initialisation");
  // Errors come back as codes (turned into vnr::Error), not as an abort inside the library.
  MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
  MPI_Comm_rank(MPI_COMM_WORLD, &g_rank);
  MPI_Comm_size(MPI_COMM_WORLD, &g_size);
  g_active = true;
}

Session::~Session() {
  g_active = false;
  MPI_Finalize();
}

bool active() { return g_active; }
int rank() { return g_rank; }
int size() { return g_size; }
int local_size() {
  const char* v = std::getenv("OMPI_COMM_WORLD_LOCAL_SIZE");
  const int n = v ? std::atoi(v) : 1;
  return n > 0 ? n : 1;
}

int local_rank() {
  for (const char* name : {"OMPI_COMM_WORLD_LOCAL_RANK", "MPI_LOCALRANKID", "SLURM_LOCALID"})
    if (const char* v = std::getenv(name); v && *v) return std::max(0, std::atoi(v));
  return 0;
}

void agree(const std::string& phase, const std::function<void()>& work) {
  std::string message;
  bool failed = false;
  try {
    work();
  } catch (const std::bad_alloc&) {
    failed = true, message = "out of memory";
  } catch (const std::exception& e) {
    failed = true, message = e.what();
  }
  if (!g_active) {
    if (failed) throw RankFailure(message);
    return;
  }
  // The lowest failing rank speaks for all; the count says whether it was alone.
  int mine = failed ? g_rank : g_size, first = g_size, count = 0, one = failed ? 1 : 0;
  check_mpi(MPI_Allreduce(&mine, &first, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD), "allreduce");
  if (first == g_size) return;
  check_mpi(MPI_Allreduce(&one, &count, 1, MPI_INT, MPI_SUM, MPI_COMM_WORLD), "allreduce");
  message = broadcast(message, first);
  // Every rank failing is usually one cause (a missing file): said once, as the lowest rank saw it.
  std::string text = count == g_size && g_size > 1
                         ? fmt::format("all {} ranks failed {}: {}", g_size, phase, message)
                         : fmt::format("rank {} of {} failed {}: {}", first, g_size, phase, message);
  if (count > 1 && count < g_size) text += fmt::format(" ({} other rank{} failed too)", count - 1, count == 2 ? "" : "s");
  throw RankFailure(text);
}

void barrier() {
  if (g_active) check_mpi(MPI_Barrier(MPI_COMM_WORLD), "barrier");
}

double sum(double v) {
  double out = v;
  if (g_active) check_mpi(MPI_Allreduce(&v, &out, 1, MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD), "allreduce");
  return out;
}

int64_t sum(int64_t v) {
  int64_t out = v;
  if (g_active) check_mpi(MPI_Allreduce(&v, &out, 1, MPI_INT64_T, MPI_SUM, MPI_COMM_WORLD), "allreduce");
  return out;
}

double max(double v) {
  double out = v;
  if (g_active) check_mpi(MPI_Allreduce(&v, &out, 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD), "allreduce");
  return out;
}

std::string broadcast(const std::string& s, int root) {
  if (!g_active) return s;
  int64_t n = int64_t(s.size());
  check_mpi(MPI_Bcast(&n, 1, MPI_INT64_T, root, MPI_COMM_WORLD), "broadcast");
  std::string out = g_rank == root ? s : std::string(size_t(n), '\0');
  if (n > 0) check_mpi(MPI_Bcast(out.data(), int(n), MPI_CHAR, root, MPI_COMM_WORLD), "broadcast");
  return out;
}

std::vector<std::string> gather(const std::string& s, int root) {
  if (!g_active) return {s};
  const std::vector<int64_t> lengths = all_gather(int64_t(s.size()));
  std::vector<int> counts(lengths.size()), offsets(lengths.size());
  int64_t total = 0;
  for (size_t r = 0; r < lengths.size(); ++r) {
    if (total + lengths[r] > INT32_MAX) fail("MPI gather: more than 2 GiB of text");
    counts[r] = int(lengths[r]), offsets[r] = int(total), total += lengths[r];
  }
  std::string all(g_rank == root ? size_t(total) : 0, '\0');
  check_mpi(MPI_Gatherv(s.data(), int(s.size()), MPI_CHAR, all.data(), counts.data(), offsets.data(), MPI_CHAR, root,
                    MPI_COMM_WORLD),
        "gather");
  std::vector<std::string> out;
  if (g_rank == root)
    for (size_t r = 0; r < lengths.size(); ++r) out.push_back(all.substr(size_t(offsets[r]), size_t(counts[r])));
  return out;
}

std::vector<int64_t> all_gather(int64_t v) {
  std::vector<int64_t> out(size_t(g_size), v);
  if (g_active) check_mpi(MPI_Allgather(&v, 1, MPI_INT64_T, out.data(), 1, MPI_INT64_T, MPI_COMM_WORLD), "allgather");
  return out;
}

void abort_all(int code) {
  if (g_active) MPI_Abort(MPI_COMM_WORLD, code);
  std::exit(code);
}

}  // namespace vnr::mpi
