// Single-thread cost of the grid encoding per level (forward gather and backward scatter) for the
// paper and small configs on random points — where each level sits between cache-resident and DRAM-bound.
#include <benchmark/benchmark.h>
#include <cstdlib>
#include <vector>
#include "vnr/core/rng.h"
#include "vnr/nn/cpu_kernels.h"
#include "vnr/nn/network.h"
#include "vnr/volume/volume.h"

namespace {

struct Fixture {
  explicit Fixture(const char* preset = "paper") : net(vnr::preset_config(preset)) { init(); }
  vnr::Network net;
  std::vector<float> x, y, z, X0, dEnc;
  void init() {
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
Fixture& small_fixture() {
  static Fixture f("small");
  return f;
}
// Level benchmarks: arg = level for the paper config, 100 + level for the small one.
Fixture& level_fixture(int64_t arg) { return arg >= 100 ? small_fixture() : fixture(); }

// The kernels directly, for a layout of one level too: F as the encoding factory would pick it.
static void grid_encode(const vnr::GridLayout& g, const uint16_t* table, const float* x, const float* y, const float* z,
                 int n, float* X0) {
  vnr::with_feature_count(g.n_features, [&](auto F) { vnr::kernels::grid_encode<F()>(g, table, x, y, z, n, X0); });
}
static void grid_backward_level(const vnr::GridLayout& g, uint32_t level, const float* x, const float* y, const float* z,
                         int64_t n, const float* dEnc, uint32_t in_pad, int chunk, float* grad) {
  vnr::with_feature_count(g.n_features, [&](auto F) {
    vnr::kernels::grid_backward_level<F()>(g, level, x, y, z, n, dEnc, in_pad, chunk, grad);
  });
}

// Whole encodings (all levels) of 65,536 random points, paper (arg 0) and small (arg 1) configs.
void BM_GridEncode(benchmark::State& state) {
  Fixture& f = state.range(0) ? small_fixture() : fixture();
  for (auto _ : state)
    for (int c = 0; c < (1 << 16); c += vnr::kChunk)
      grid_encode(f.net.grid(), f.net.grid_half(), f.x.data() + c, f.y.data() + c, f.z.data() + c, vnr::kChunk,
                  f.X0.data());
  state.counters["ns/sample"] = benchmark::Counter(double(state.iterations()) * (1 << 16),
                                                   benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_GridEncode)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);


// Encodes 65,536 random points in chunks of 256 with a layout holding only level `l`. Repeated
// iterations keep that level's table warm in L2/L3, so this is the cache-resident cost per level;
// in a training step the tables are cold (Adam and the gradient scatter stream the whole parameter
// set through the caches) and the large levels cost more (BM_GridEncode measures all levels together).
void BM_GridEncodeLevel(benchmark::State& state) {
  Fixture& f = level_fixture(state.range(0));
  vnr::GridLayout one = f.net.grid();
  const int l = int(state.range(0) % 100);
  one.levels[0] = one.levels[l];
  one.n_levels = 1;
  for (auto _ : state)
    for (int c = 0; c < (1 << 16); c += vnr::kChunk)
      grid_encode(one, f.net.grid_half(), f.x.data() + c, f.y.data() + c, f.z.data() + c, vnr::kChunk, f.X0.data());
  state.counters["ns/sample"] = benchmark::Counter(double(state.iterations()) * (1 << 16),
                                                   benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

void BM_GridBackwardLevel(benchmark::State& state) {
  Fixture& f = level_fixture(state.range(0));
  std::vector<float> grad(f.net.grid_params(), 0.0f);
  for (auto _ : state)
    grid_backward_level(f.net.grid(), uint32_t(state.range(0) % 100), f.x.data(), f.y.data(), f.z.data(), 1 << 16,
                        f.dEnc.data(), f.net.mlp().in_pad, vnr::kChunk, grad.data());
  state.counters["ns/sample"] = benchmark::Counter(double(state.iterations()) * (1 << 16),
                                                   benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

BENCHMARK(BM_GridEncodeLevel)->DenseRange(0, 7)->DenseRange(100, 103)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_GridBackwardLevel)->DenseRange(0, 7)->DenseRange(100, 103)->Unit(benchmark::kMillisecond);

}  // namespace

namespace {
// Ground-truth lookups of 65,536 random points in a 256^3 volume (VNR_BENCH_DIM changes the size).
void BM_GridLookup(benchmark::State& state) {
  static vnr::Volume vol = [] {
    vnr::Volume v;
    const char* e = getenv("VNR_BENCH_DIM");
    int64_t d = e ? atoi(e) : 256;
    v.dims = {d, d, d};
    v.source_dtype = vnr::DType::UInt8;
    v.lo = 0;
    v.hi = 255;
    vnr::Pcg32 r(1);
    v.data.resize(v.dims.count());
    for (auto& d : v.data) d = float(r.next_uint() & 255) / 255.0f;
    return v;
  }();
  vnr::GridView g = vnr::view_of(vol);
  Fixture& f = fixture();
  std::vector<float> out(vnr::kChunk);
  for (auto _ : state)
    for (int c = 0; c < (1 << 16); c += vnr::kChunk)
      vnr::grid_lookup_batch(g, f.x.data() + c, f.y.data() + c, f.z.data() + c, vnr::kChunk, out.data());
  state.counters["ns/sample"] = benchmark::Counter(double(state.iterations()) * (1 << 16),
                                                   benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_GridLookup)->Unit(benchmark::kMillisecond);
}  // namespace
