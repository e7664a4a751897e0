// Single-thread cost of the grid encoding per level (forward gather and backward scatter) for the
// paper config on random points — where each level sits between cache-resident and DRAM-bound.
#include <benchmark/benchmark.h>
#include <vector>
#include "vnr/core/rng.h"
#include "vnr/nn/cpu_kernels.h"
#include "vnr/nn/network.h"

namespace {

struct Fixture {
  vnr::Network net{vnr::preset_config("paper")};
  std::vector<float> x, y, z, X0, dEnc;
  Fixture() {
    net.init_params(1);
    vnr::Pcg32 rng(3);
    const int n = 1 << 16;
    for (int i = 0; i < n; ++i) x.push_back(rng.next_float()), y.push_back(rng.next_float()), z.push_back(rng.next_float());
    X0.resize(size_t(net.mlp().in_pad) * vnr::kChunk);
    dEnc.assign(size_t(net.mlp().in_pad) * n, 1e-3f);
  }
};

Fixture& fixture() {
  static Fixture f;
  return f;
}

// Encodes 65,536 random points in chunks of 256 with a layout holding only level `l`.
void BM_GridEncodeLevel(benchmark::State& state) {
  Fixture& f = fixture();
  vnr::GridLayout one = f.net.grid();
  const int l = int(state.range(0));
  one.levels[0] = one.levels[l];
  one.n_levels = 1;
  for (auto _ : state)
    for (int c = 0; c < (1 << 16); c += vnr::kChunk)
      vnr::kernels::grid_encode(one, f.net.grid_half(), f.x.data() + c, f.y.data() + c, f.z.data() + c, vnr::kChunk,
                                f.X0.data());
  state.counters["ns/sample"] = benchmark::Counter(double(state.iterations()) * (1 << 16),
                                                   benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

void BM_GridBackwardLevel(benchmark::State& state) {
  Fixture& f = fixture();
  std::vector<float> grad(f.net.grid_params(), 0.0f);
  for (auto _ : state)
    vnr::kernels::grid_backward_level(f.net.grid(), uint32_t(state.range(0)), f.x.data(), f.y.data(), f.z.data(),
                                      1 << 16, f.dEnc.data(), f.net.mlp().in_pad, vnr::kChunk, grad.data());
  state.counters["ns/sample"] = benchmark::Counter(double(state.iterations()) * (1 << 16),
                                                   benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

BENCHMARK(BM_GridEncodeLevel)->DenseRange(0, 7)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_GridBackwardLevel)->DenseRange(0, 7)->Unit(benchmark::kMillisecond);

}  // namespace
