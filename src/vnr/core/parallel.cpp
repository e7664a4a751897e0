#include "vnr/core/parallel.h"

namespace vnr {
int num_threads() { return omp_get_max_threads(); }
void set_num_threads(int n) {
  if (n <= 0) n = omp_get_num_procs();
  omp_set_num_threads(n);
}
}  // namespace vnr
