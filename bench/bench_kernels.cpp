// Single-thread throughput of the MLP kernels (GFLOP/s, 2*rows*cols*n FLOP per call) at the
// trainer's chunk size. This file also provides main() for vnr_bench_kernels.
#include <benchmark/benchmark.h>
#include <hwy/aligned_allocator.h>

#include <random>

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#define VNR_BENCH_PEAK 1
#endif

#include "vnr/nn/mlp_kernels.h"

namespace k = vnr::kernels;

namespace {

hwy::AlignedFreeUniquePtr<float[]> random_buf(size_t count, unsigned seed, float lo = -1.0f) {
  auto p = hwy::AllocateAligned<float>(count);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(lo, 1.0f);
  for (size_t i = 0; i < count; ++i) p[i] = u(rng);
  return p;
}

void set_flops(benchmark::State& state, int rows, int cols, int n) {
  state.counters["GFLOP/s"] = benchmark::Counter(
      2.0 * rows * cols * n * double(state.iterations()) * 1e-9, benchmark::Counter::kIsRate);
}

// Args: rows, cols, n.
void BM_Fwd(benchmark::State& state) {
  const int rows = int(state.range(0)), cols = int(state.range(1)), n = int(state.range(2));
  auto W = random_buf(size_t(rows) * cols, 1), X = random_buf(size_t(cols) * n, 2);
  auto Y = hwy::AllocateAligned<float>(size_t(rows) * n);
  for (auto _ : state) {
    k::matmul_fwd(W.get(), rows, cols, X.get(), Y.get(), n, true);
    benchmark::DoNotOptimize(Y.get());
    benchmark::ClobberMemory();
  }
  set_flops(state, rows, cols, n);
}

void BM_BwdData(benchmark::State& state) {
  const int rows = int(state.range(0)), cols = int(state.range(1)), n = int(state.range(2));
  auto W = random_buf(size_t(rows) * cols, 1), dY = random_buf(size_t(rows) * n, 2);
  auto mask = random_buf(size_t(cols) * n, 3), dX = hwy::AllocateAligned<float>(size_t(cols) * n);
  for (auto _ : state) {
    k::matmul_bwd_data(W.get(), rows, cols, dY.get(), mask.get(), dX.get(), n);
    benchmark::DoNotOptimize(dX.get());
    benchmark::ClobberMemory();
  }
  set_flops(state, rows, cols, n);
}

void BM_BwdWeights(benchmark::State& state) {
  const int rows = int(state.range(0)), cols = int(state.range(1)), n = int(state.range(2));
  auto dY = random_buf(size_t(rows) * n, 1), X = random_buf(size_t(cols) * n, 2, 0.0f);
  auto dW = random_buf(size_t(rows) * cols, 3);
  for (auto _ : state) {
    k::matmul_bwd_weights(dY.get(), rows, X.get(), cols, n, dW.get());
    benchmark::DoNotOptimize(dW.get());
    benchmark::ClobberMemory();
  }
  set_flops(state, rows, cols, n);
}

// Square hidden layers at widths 16..128 with n = 256, plus the paper's input (64 -> 64 is square)
// and output (64 -> 1) layers and a larger chunk.
void Shapes(benchmark::internal::Benchmark* b) {
  b->ArgNames({"rows", "cols", "n"});
  for (int w : {16, 32, 64, 128}) b->Args({w, w, 256});
  b->Args({1, 64, 256});
  b->Args({64, 64, 512});
}

#ifdef VNR_BENCH_PEAK
// Register-only zmm FMA loop (24 independent chains): the machine's ceiling at the moment of the
// run, so the kernels' GFLOP/s can be read as a fraction of it on this shared, noisy VM.
__attribute__((target("avx512f"), noinline)) float fma_peak_loop(long iters) {
  __m512 acc[24];
#pragma GCC unroll 24
  for (int j = 0; j < 24; ++j) acc[j] = _mm512_set1_ps(0.001f * j);
  const __m512 a = _mm512_set1_ps(0.9999f), b = _mm512_set1_ps(1e-6f);
  for (long i = 0; i < iters; ++i) {
#pragma GCC unroll 24
    for (int j = 0; j < 24; ++j) acc[j] = _mm512_fmadd_ps(acc[j], a, b);
  }
  __m512 s = acc[0];
#pragma GCC unroll 24
  for (int j = 1; j < 24; ++j) s = _mm512_add_ps(s, acc[j]);
  return _mm512_reduce_add_ps(s);
}

void BM_FmaPeak(benchmark::State& state) {
  if (!__builtin_cpu_supports("avx512f")) {
    state.SkipWithError("no AVX-512");
    return;
  }
  constexpr long kIters = 4096;
  long iters = kIters;
  for (auto _ : state) {
    benchmark::DoNotOptimize(iters);  // the loop is a pure function: keep it from being hoisted
    benchmark::DoNotOptimize(fma_peak_loop(iters));
  }
  state.counters["GFLOP/s"] = benchmark::Counter(
      kIters * 24 * 32.0 * double(state.iterations()) * 1e-9, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_FmaPeak);
#endif

BENCHMARK(BM_Fwd)->Apply(Shapes);
BENCHMARK(BM_BwdData)->Apply(Shapes);
BENCHMARK(BM_BwdWeights)->Apply(Shapes);

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::AddCustomContext("simd_target", k::simd_target_name());
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
