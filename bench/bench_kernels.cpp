// Single-thread throughput of the MLP kernels (GFLOP/s, 2*rows*cols*n FLOP per call) at the
// trainer's chunk size. This file also provides main() for vnr_bench_kernels.
#include <benchmark/benchmark.h>
#include <hwy/aligned_allocator.h>

#include <random>

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#define VNR_BENCH_PEAK 1
#endif

#include "vnr/nn/mlp_bf16.h"
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

// The bf16 forward kernel (inference), same shapes: hidden rows give bf16 pairs with ReLU, a single
// output row fp32 values.
void BM_FwdBf16(benchmark::State& state) {
  if (!k::bf16_supported()) {
    state.SkipWithError("no AVX512-BF16");
    return;
  }
  const int rows = int(state.range(0)), cols = int(state.range(1)), n = int(state.range(2));
  const int kp = (cols + 1) / 2;
  auto W = random_buf(size_t(rows) * cols, 1), X = random_buf(size_t(cols) * n, 2);
  auto Wp = hwy::AllocateAligned<uint32_t>(size_t(rows) * kp), Xp = hwy::AllocateAligned<uint32_t>(size_t(kp) * n);
  auto Y = hwy::AllocateAligned<float>(size_t(rows) * n);
  k::weights_to_bf16_pairs(W.get(), rows, cols, cols, Wp.get());
  k::activations_to_bf16_pairs(X.get(), cols, n, Xp.get());
  for (auto _ : state) {
    if (rows % 2 == 0)
      k::matmul_fwd_bf16_relu(Wp.get(), rows, kp, Xp.get(), reinterpret_cast<uint32_t*>(Y.get()), n);
    else
      k::matmul_fwd_bf16_linear(Wp.get(), rows, kp, Xp.get(), Y.get(), n);
    benchmark::DoNotOptimize(Y.get());
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
// The peak loops' 24 independent accumulator chains: their start values and their sum (which keeps
// the loop's work alive). avx512f only, so both loops' wider targets can inline them.
constexpr int kPeakChains = 24;
__attribute__((target("avx512f"), always_inline)) inline void peak_init(__m512 (&acc)[kPeakChains]) {
#pragma GCC unroll 24
  for (int j = 0; j < kPeakChains; ++j) acc[j] = _mm512_set1_ps(0.001f * j);
}
__attribute__((target("avx512f"), always_inline)) inline float peak_sum(const __m512 (&acc)[kPeakChains]) {
  __m512 s = acc[0];
#pragma GCC unroll 24
  for (int j = 1; j < kPeakChains; ++j) s = _mm512_add_ps(s, acc[j]);
  alignas(64) float lanes[16];
  _mm512_store_ps(lanes, s);
  return lanes[0];
}

// Register-only zmm FMA loop: the machine's ceiling at the moment of the run, so the kernels'
// GFLOP/s can be read as a fraction of it on this shared, noisy VM.
__attribute__((target("avx512f"), noinline)) float fma_peak_loop(long iters) {
  __m512 acc[kPeakChains];
  peak_init(acc);
  const __m512 a = _mm512_set1_ps(0.9999f), b = _mm512_set1_ps(1e-6f);
  for (long i = 0; i < iters; ++i) {
#pragma GCC unroll 24
    for (int j = 0; j < kPeakChains; ++j) acc[j] = _mm512_fmadd_ps(acc[j], a, b);
  }
  return peak_sum(acc);
}

// Times `loop` (kIters iterations of kPeakChains independent vector ops of flop_per_op each).
template <class Loop>
void run_peak(benchmark::State& state, bool supported, Loop loop, double flop_per_op) {
  if (!supported) {
    state.SkipWithError("instruction not supported on this CPU");
    return;
  }
  constexpr long kIters = 4096;
  long iters = kIters;
  for (auto _ : state) {
    benchmark::DoNotOptimize(iters);  // the loop is a pure function: keep it from being hoisted
    benchmark::DoNotOptimize(loop(iters));
  }
  state.counters["GFLOP/s"] = benchmark::Counter(
      kIters * kPeakChains * flop_per_op * double(state.iterations()) * 1e-9, benchmark::Counter::kIsRate);
}

void BM_FmaPeak(benchmark::State& state) { run_peak(state, __builtin_cpu_supports("avx512f"), fma_peak_loop, 32.0); }
BENCHMARK(BM_FmaPeak);

// The same loop with vdpbf16ps (two multiply-adds per fp32 lane): the ceiling of the bf16 kernels.
__attribute__((target("avx512f,avx512bw,avx512bf16"), noinline)) float bf16_peak_loop(long iters) {
  __m512 acc[kPeakChains];
  peak_init(acc);
  const __m512bh a = (__m512bh)_mm512_set1_epi16(0x3f80), b = (__m512bh)_mm512_set1_epi16(0x3380);
  for (long i = 0; i < iters; ++i) {
#pragma GCC unroll 24
    for (int j = 0; j < kPeakChains; ++j) acc[j] = _mm512_dpbf16_ps(acc[j], a, b);
  }
  return peak_sum(acc);
}

void BM_Bf16DotPeak(benchmark::State& state) { run_peak(state, k::bf16_supported(), bf16_peak_loop, 64.0); }
BENCHMARK(BM_Bf16DotPeak);
#endif

BENCHMARK(BM_Fwd)->Apply(Shapes);
BENCHMARK(BM_FwdBf16)->Apply(Shapes);
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
