#pragma once
#include <algorithm>
#include <atomic>
#include <cstdint>
#include <omp.h>
#include "vnr/threads.h"

namespace vnr {

// The CPU backend's parallel_for: OpenMP with a *static* schedule, so that which thread
// handles which index is a pure function of (n, thread count): results that reduce per-thread
// partials in thread order are deterministic for a given thread count.

template <typename F>
void parallel_for(int64_t n, F&& f) {
#pragma omp parallel for schedule(static)
  for (int64_t i = 0; i < n; ++i) f(i);
}

// Calls f(begin, end) on contiguous ranges of at most `grain` indices.
template <typename F>
void parallel_for_range(int64_t n, int64_t grain, F&& f) {
  if (grain < 1) grain = 1;
  int64_t chunks = (n + grain - 1) / grain;
  if (chunks <= 1) {
    if (n > 0) f(int64_t(0), n);
    return;
  }
#pragma omp parallel for schedule(static)
  for (int64_t c = 0; c < chunks; ++c) {
    int64_t b = c * grain, e = b + grain < n ? b + grain : n;
    f(b, e);
  }
}

// Inside parallel_threads: f(i) for the indices [0, n) this thread claims from `next` (shared by the
// threads, starting at 0), one at a time, whichever thread is free first. Only for work whose
// results do not depend on the thread that runs it: a core slowed by another job then takes less.
template <typename F>
void for_each_claimed(std::atomic<int64_t>& next, int64_t n, F&& f) {
  for (int64_t i; (i = next.fetch_add(1, std::memory_order_relaxed)) < n;) f(i);
}

// Runs f(thread_index, n_threads) once on every worker thread.
template <typename F>
void parallel_threads(F&& f) {
#pragma omp parallel
  { f(omp_get_thread_num(), omp_get_num_threads()); }
}

// parallel_for_range's ranges, each claimed by whichever thread is free (for_each_claimed): only for
// work whose results do not depend on the thread (rendering, element-wise updates), so a core slowed
// by another job takes fewer ranges instead of holding up the rest.
template <typename F>
void parallel_for_claimed(int64_t n, int64_t grain, F&& f) {
  if (grain < 1) grain = 1;
  const int64_t chunks = (n + grain - 1) / grain;
  if (chunks <= 1) {
    if (n > 0) f(int64_t(0), n);
    return;
  }
  std::atomic<int64_t> next{0};
  parallel_threads([&](int, int) {
    for_each_claimed(next, chunks, [&](int64_t c) { f(c * grain, std::min(n, (c + 1) * grain)); });
  });
}

}  // namespace vnr

#if defined(__CUDACC__)
namespace vnr {

// The CUDA backend's parallel_for: the same per-index functor, f(i) for i in [0, n), as a kernel of one
// thread per index on `stream` (f is copied to the GPU by value; its operator() is VNR_HD or
// __device__). The caller checks the launch (VNR_CUDA_LAUNCHED in cuda/common.h).
template <class F>
__global__ void parallel_for_kernel(int64_t n, F f) {
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i < n) f(i);
}

template <class F>
void parallel_for(cudaStream_t stream, int64_t n, const F& f, int threads = 256) {
  if (n > 0) parallel_for_kernel<<<unsigned((n + threads - 1) / threads), unsigned(threads), 0, stream>>>(n, f);
}

}  // namespace vnr
#endif
