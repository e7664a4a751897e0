// Single-thread throughput of PointEvaluator::eval (the in-shader renderer's per-sample query) next
// to batched Network::infer on the same points, so the ratio is visible. Counters: items_per_second
// = points/s; per_pt = time per point.
//   Models: Paper (HashGrid 8x8, 2^19, MLP 64x4), Ngp (HashGrid 16x2, 2^19, MLP 64x4), Small (4x2, 16x2);
//   3-5: the same with bf16 inference.
//   Points: Random (uniform in the cube: every corner a cold line in the large levels) or Ray
//   (ray-marching order: 256 steps of 1/256 along random rays, so consecutive queries share lines).
//   Encode / Mlp variants time the two halves of eval() alone (Mlp on precomputed encodings).
//   Eval args: skip = compaction of zero ReLU outputs on; pf = PointEvaluator::prefetch(next point)
//   before each eval (what a ray loop can do: the next sample's position is known).
#include <benchmark/benchmark.h>

#include <cmath>
#include <memory>
#include <random>
#include <vector>

#include "vnr/core/parallel.h"
#include "vnr/nn/mlp_bf16.h"
#include "vnr/nn/network.h"
#include "vnr/nn/point_eval.h"

using namespace vnr;

namespace {

Json ngp_config() {
  Json c = preset_config("paper");
  c["encoding"] = {{"otype", "HashGrid"},       {"n_levels", 16},       {"n_features_per_level", 2},
                   {"log2_hashmap_size", 19},   {"base_resolution", 16}, {"per_level_scale", 1.5}};
  return c;
}

Json config_of(int model) {
  switch (model) {
    case 0: return preset_config("paper");
    case 1: return ngp_config();
    default: return preset_config("small");
  }
}

// One network per model, initialised once (tcnn init, grid U[-1, 1] so features are O(1)).
// Models 3-5 are models 0-2 with bf16 inference (Precision::BF16, AVX512-BF16 CPUs).
const Network& model_net(int model) {
  static std::unique_ptr<Network> nets[6];
  if (!nets[model]) {
    nets[model] = std::make_unique<Network>(config_of(model % 3));
    Network& net = *nets[model];
    net.init_params(1);
    std::mt19937 gen(2);
    std::uniform_real_distribution<float> U(-1.f, 1.f);
    net.edit_params([&](float* p, size_t) {
      float* table = p + net.mlp().n_params;
      for (uint64_t i = 0; i < net.grid_params(); ++i) table[i] = U(gen);
    });
    if (model >= 3) net.set_inference_precision(parse_precision("bf16"));
  }
  return *nets[model];
}

constexpr int kPoints = 1 << 16;

// kPoints points, interleaved xyz: random in the cube, or 256 consecutive steps along random rays.
const std::vector<float>& points(bool ray) {
  static std::vector<float> p[2];
  std::vector<float>& v = p[ray];
  if (v.empty()) {
    std::mt19937 gen(ray ? 7 : 6);
    std::uniform_real_distribution<float> U(0.f, 1.f);
    v.resize(3 * size_t(kPoints));
    if (!ray) {
      for (auto& c : v) c = U(gen);
    } else {
      const int steps = 256;
      for (int r = 0; r < kPoints / steps; ++r) {
        float o[3] = {U(gen), U(gen), U(gen)}, dir[3];
        float len = 0;
        for (auto& c : dir) c = U(gen) - 0.5f, len += c * c;
        len = std::sqrt(len);
        for (int s = 0; s < steps; ++s)
          for (int a = 0; a < 3; ++a) {
            float x = o[a] + dir[a] / len * (float(s) / steps);
            x -= std::floor(x);  // wrap into [0, 1)
            v[3 * size_t(r * steps + s) + a] = x;
          }
      }
    }
  }
  return v;
}

void set_rate(benchmark::State& state, int64_t pts) {
  state.SetItemsProcessed(pts);
  state.counters["per_pt"] = benchmark::Counter(double(pts), benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

// Args: model, ray, skip zeros, prefetch (pe.prefetch(next point) before each eval, as a ray loop can).
void BM_PointEval_Eval(benchmark::State& state) {
  const Network& net = model_net(int(state.range(0)));
  const std::vector<float>& p = points(state.range(1) != 0);
  const PointEvaluator pe(net, state.range(2) != 0);
  const bool pf = state.range(3) != 0;
  int64_t done = 0;
  float sink = 0;
  for (auto _ : state) {
    if (pf) {
      for (int i = 0; i < kPoints; ++i) {
        const int nx = i + 1 < kPoints ? i + 1 : i;
        pe.prefetch(p[3 * nx], p[3 * nx + 1], p[3 * nx + 2]);
        sink += pe.eval(p[3 * i], p[3 * i + 1], p[3 * i + 2]);
      }
    } else {
      for (int i = 0; i < kPoints; ++i) sink += pe.eval(p[3 * i], p[3 * i + 1], p[3 * i + 2]);
    }
    done += kPoints;
  }
  benchmark::DoNotOptimize(sink);
  set_rate(state, done);
  state.SetLabel(pe.simd_target());
}

// Batched Network::infer over the same points on one thread.
void BM_PointEval_Infer(benchmark::State& state) {
  const Network& net = model_net(int(state.range(0)));
  const std::vector<float>& p = points(state.range(1) != 0);
  std::vector<float> out(kPoints);
  const int threads = num_threads();
  set_num_threads(1);
  int64_t done = 0;
  for (auto _ : state) {
    net.infer(p.data(), kPoints, out.data());
    benchmark::DoNotOptimize(out.data());
    done += kPoints;
  }
  set_num_threads(threads);
  set_rate(state, done);
}

// The encoding half alone (padded encoding into a buffer).
void BM_PointEval_Encode(benchmark::State& state) {
  const Network& net = model_net(int(state.range(0)));
  const std::vector<float>& p = points(state.range(1) != 0);
  const PointEvaluator pe(net);
  std::vector<float> enc(pe.in_pad());
  int64_t done = 0;
  for (auto _ : state) {
    for (int i = 0; i < kPoints; ++i) {
      pe.encode(p[3 * i], p[3 * i + 1], p[3 * i + 2], enc.data());
      benchmark::DoNotOptimize(enc.data());
    }
    done += kPoints;
  }
  set_rate(state, done);
}

// The MLP half alone, on precomputed encodings of the points (4096 of them, cycling: they stay in L2).
void BM_PointEval_Mlp(benchmark::State& state) {
  const Network& net = model_net(int(state.range(0)));
  const std::vector<float>& p = points(false);
  const PointEvaluator pe(net, state.range(2) != 0);
  const int n = 4096;
  const size_t ip = pe.in_pad();
  std::vector<float> enc(ip * n);
  for (int i = 0; i < n; ++i) pe.encode(p[3 * i], p[3 * i + 1], p[3 * i + 2], enc.data() + ip * i);
  int64_t done = 0;
  float sink = 0;
  for (auto _ : state) {
    for (int i = 0; i < n; ++i) sink += pe.mlp(enc.data() + ip * i);
    done += n;
  }
  benchmark::DoNotOptimize(sink);
  set_rate(state, done);
}

void Models(benchmark::internal::Benchmark* b) {
  b->ArgNames({"model", "ray", "skip", "pf"});
  for (int m : {0, 1, 2})
    for (int ray : {0, 1})
      for (int pf : {0, 1}) b->Args({m, ray, 1, pf});
  if (kernels::bf16_supported())
    for (int m : {3, 4, 5}) b->Args({m, 1, 1, 1});
  b->Args({0, 0, 0, 0});
  b->Args({1, 0, 0, 0});
  b->Unit(benchmark::kMillisecond);
}

void ModelsInfer(benchmark::internal::Benchmark* b) {
  b->ArgNames({"model", "ray"});
  for (int m : {0, 1, 2})
    for (int ray : {0, 1}) b->Args({m, ray});
  if (kernels::bf16_supported())
    for (int m : {3, 4, 5}) b->Args({m, 1});
  b->Unit(benchmark::kMillisecond);
}

void ModelsMlp(benchmark::internal::Benchmark* b) {
  b->ArgNames({"model", "ray", "skip"});
  for (int m : {0, 1, 2})
    for (int skip : {1, 0}) b->Args({m, 0, skip});
  if (kernels::bf16_supported())
    for (int m : {3, 4, 5})
      for (int skip : {1, 0}) b->Args({m, 0, skip});
  b->Unit(benchmark::kMicrosecond);
}

BENCHMARK(BM_PointEval_Eval)->Apply(Models);
BENCHMARK(BM_PointEval_Infer)->Apply(ModelsInfer);
BENCHMARK(BM_PointEval_Encode)->Apply(ModelsInfer);
BENCHMARK(BM_PointEval_Mlp)->Apply(ModelsMlp);

}  // namespace
