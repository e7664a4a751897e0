// ThreadSanitizer build only (scripts/sanitize.sh thread): checks the checker. `clean` shares data the way
// the trainer does (per-thread slots, claimed chunks, results read after the region) and must give no
// report: proof that Archer tells TSan what OpenMP's barriers order. `race` has every thread add to one
// plain int and must be reported: proof that races inside our parallel_threads regions are seen.
#include <atomic>
#include <cstdio>
#include <cstring>
#include <vector>
#include "vnr/core/parallel.h"

namespace {

int run_clean() {
  vnr::set_num_threads(4);
  const int64_t n = 64;
  std::vector<double> per_thread(64, 0.0), per_chunk(size_t(n), 0.0);
  std::atomic<int64_t> next{0};
  for (int rep = 0; rep < 3; ++rep) {  // regions reuse the pool's threads: writes of one, reads of the next
    next.store(0);
    vnr::parallel_threads([&](int t, int nt) {
      for (int64_t i = t; i < n; i += nt) per_thread[size_t(t)] += double(i);
      vnr::for_each_claimed(next, n, [&](int64_t i) { per_chunk[size_t(i)] += 1.0; });
    });
    vnr::parallel_for(n, [&](int64_t i) { per_chunk[size_t(i)] *= 1.0; });
  }
  double sum = 0, chunks = 0;
  for (double v : per_thread) sum += v;
  for (double v : per_chunk) chunks += v;
  std::printf("sum %.0f chunks %.0f\n", sum, chunks);
  return sum == 3.0 * double(n * (n - 1) / 2) && chunks == 3.0 * double(n) ? 0 : 1;
}

int run_race() {
  vnr::set_num_threads(4);
  int shared = 0;
  vnr::parallel_threads([&](int, int) { shared += 1; });  // the bug TSan must report
  std::printf("shared %d\n", shared);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 2 && std::strcmp(argv[1], "clean") == 0) return run_clean();
  if (argc == 2 && std::strcmp(argv[1], "race") == 0) return run_race();
  std::fprintf(stderr, "usage: tsan_openmp_canary clean|race\n");
  return 2;
}
