// vnr bench train|infer: throughput on a real volume, median over timed steps, plus the MLP alone
// (GFLOP/s against the per-sample FLOP count) so it can be compared with the machine's FMA peak.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <array>
#include <string>
#include <vector>
#include "cli.h"
#include "vnr/core/error.h"
#include "vnr/core/parallel.h"
#include "vnr/core/progress.h"
#include "vnr/core/rng.h"
#include "vnr/cuda/cuda.h"
#include "vnr/nn/config.h"
#include "vnr/nn/mlp_kernels.h"
#include "vnr/model.h"
#include "vnr/train/trainer.h"

namespace vnr::cli {
namespace {

struct BenchArgs {
  std::string what, volume, config = "paper", report, device = "auto", mlp = "auto", precision = "auto";
  double seconds = 10;
  int64_t batch = 65536;
  int threads = 0;
  VolumeArgs vol;
};

// MLP forward (+ backward when training) alone over chunks, all threads: GFLOP/s.
double mlp_gflops(const Network& net, bool training, Precision train_precision, double seconds) {
  const MlpLayout& m = net.mlp();
  const int C = kChunk;
  double flops_per_chunk = net.flops_forward_per_sample() * C * (training ? 3.0 : 1.0);
  std::vector<double> per_thread(num_threads(), 0.0);
  double el = 0;
  parallel_threads([&](int t, int nt) {
    std::vector<float> X0(size_t(m.in_pad) * C, 0.5f), acts(net.acts_floats(C)), out(m.n_out * C),
        dout(m.n_out * C, 1e-3f), dW(m.n_params), dX(size_t(m.in_pad) * C), scratch(2 * m.width * C);
    Pcg32 rng(t + 1);
    for (auto& x : X0) x = rng.next_float();
    const bool bf16 = !training && net.inference_precision() == Precision::BF16;
    const std::vector<uint32_t> wp = bf16 ? net.bf16_weights() : std::vector<uint32_t>();
    std::vector<uint32_t> pairs(bf16 ? net.mlp_bf16_scratch(C) : 0);
    const bool bf16_train = training && train_precision == Precision::BF16;
    Network::Bf16TrainWeights tw;
    if (bf16_train) tw = net.bf16_train_weights();
    std::vector<uint32_t> tws(bf16_train ? net.mlp_train_bf16_scratch(C) : 0);
    auto t0 = std::chrono::steady_clock::now();
    int64_t chunks = 0;
    while (seconds_since(t0) < seconds) {
      for (int r = 0; r < 16; ++r, ++chunks) {
        if (bf16) {
          net.mlp_forward_bf16(X0.data(), C, wp.data(), pairs.data(), out.data());
          continue;
        }
        if (bf16_train) {
          net.mlp_forward_train_bf16(X0.data(), C, tw, tws.data(), out.data(), out.data());
          net.mlp_backward_train_bf16(dout.data(), C, tw, tws.data(), dW.data(), dX.data());
          continue;
        }
        net.mlp_forward(X0.data(), C, acts.data(), out.data(), out.data());
        if (training) net.mlp_backward(X0.data(), acts.data(), dout.data(), C, dW.data(), dX.data(), scratch.data());
      }
    }
    per_thread[t] = chunks * flops_per_chunk / seconds_since(t0);
  });
  for (double g : per_thread) el += g;
  return el / 1e9;
}

// The same measurements on the GPU: per-step times from groups of steps between synchronisations
// (training issues no synchronisation of its own), inference both with host transfers (the batch comes
// from and goes back to host memory) and resident on the GPU (CUDA events, no transfers).
void run_bench_cuda(const BenchArgs& a, const Volume& vol, Model& model) {
  Network& net = *model.net;
  const bool training = a.what == "train";
  const cuda::MlpPath asked = cuda::parse_mlp_path(a.mlp);
  const double flops = net.flops_forward_per_sample() * (training ? 3.0 : 1.0);
  std::vector<double> times;
  Json report = {{"mode", a.what}, {"device", "cuda"}, {"config", a.config}, {"batch", a.batch},
                 {"n_params", net.n_params()}, {"gpu", cuda::devices().at(0).name}};
  Progress bar(std::string("bench ") + a.what + " (cuda)", a.seconds, false);
  const char* path = "";
  double mlp_seconds = 0, resident_sps = 0;
  uint64_t peak = 0;
  if (training) {
    cuda::GpuTrainer tr(net, view_of(vol), cuda::GpuTrainOptions{a.batch, 1337, kChunk, asked});
    tr.run(5);  // warm-up
    tr.synchronize();
    auto t0 = std::chrono::steady_clock::now();
    int group = 8;
    while (seconds_since(t0) < a.seconds || times.size() < 3) {
      auto s0 = std::chrono::steady_clock::now();
      tr.run(group);
      tr.synchronize();
      const double per = seconds_since(s0) / group;
      for (int i = 0; i < group; ++i) times.push_back(per);
      if (per * group < 0.1 && group < 1024) group *= 2;
      bar.update(seconds_since(t0));
    }
    tr.set_profiling(true);
    tr.run(1);
    std::vector<double> ph = tr.phase_seconds();
    mlp_seconds = ph.at(1);
    report["phase_ms"] = {{"sample_encode", ph[0] * 1e3}, {"mlp_forward_loss_backward", ph[1] * 1e3},
                          {"grid_backward", ph[2] * 1e3}, {"optimizer", ph[3] * 1e3}};
    std::printf("phases of one step (ms, CUDA events): sample+encode %.3f, MLP fwd+loss+bwd %.3f, grid backward "
                "%.3f, Adam %.3f\n",
                ph[0] * 1e3, ph[1] * 1e3, ph[2] * 1e3, ph[3] * 1e3);
    path = cuda::mlp_path_name(tr.mlp_path());
    peak = tr.peak_memory_bytes();
  } else {
    ModelQuery query(model, Device::Cuda, asked);
    cuda::GpuNetwork& gn = *query.gpu();
    std::vector<float> coords(3 * a.batch), out(a.batch);
    Pcg32 rng(7);
    for (auto& c : coords) c = rng.next_float();
    query.points(coords.data(), a.batch, out.data());
    auto t0 = std::chrono::steady_clock::now();
    while (seconds_since(t0) < a.seconds || times.size() < 3) {
      auto s0 = std::chrono::steady_clock::now();
      query.points(coords.data(), a.batch, out.data());
      times.push_back(seconds_since(s0));
      bar.update(seconds_since(t0));
    }
    const int64_t n_res = std::max<int64_t>(a.batch, int64_t(1) << 22);  // enough work to fill the GPU
    const cuda::GpuNetwork::ResidentTiming rt = gn.time_resident(n_res, 20);
    resident_sps = double(n_res) / rt.seconds;
    mlp_seconds = rt.mlp_seconds * double(a.batch) / double(n_res);
    report["resident_samples_per_second"] = resident_sps;
    report["resident_batch"] = n_res;
    path = cuda::mlp_path_name(gn.mlp_path());
    peak = gn.peak_memory_bytes();
  }
  bar.finish();
  const double med = median(times), sps = a.batch / med;
  const double mlp_tflops = flops * double(a.batch) / mlp_seconds / 1e12;
  std::printf("%s %s on %s: %.1f M samples/s (median of %zu batches of %lld, %.3f ms each)%s\n", a.what.c_str(),
              a.config.c_str(), cuda::devices().at(0).name.c_str(), sps / 1e6, times.size(), (long long)a.batch,
              med * 1e3, training ? "" : " with host transfers");
  if (!training) std::printf("resident on the GPU: %.1f M samples/s\n", resident_sps / 1e6);
  std::printf("MLP (%s path): %.1f kFLOP/sample, %.2f TFLOP/s in its kernels; %.2f TFLOP/s end to end; peak GPU "
              "memory %s\n",
              path, flops / 1e3, mlp_tflops, flops * sps / 1e12, human_bytes(double(peak)).c_str());
  report.update({{"samples_per_second", sps},
                 {"batches", times.size()},
                 {"ms_median", med * 1e3},
                 {"mlp_path", path},
                 {"mlp_flops_per_sample", flops},
                 {"mlp_tflops", mlp_tflops},
                 {"tflops_end_to_end", flops * sps / 1e12},
                 {"peak_gpu_memory_bytes", peak}});
  write_report(a.report, report);
}

void run_bench(const BenchArgs& a) {
  set_num_threads(a.threads);
  const Device dev = cuda::resolve_device(a.device);
  Volume vol = load_volume(describe_volume(a.volume, a.vol.raw()), a.vol.load());
  Model model = create_model(load_config(a.config), vol, 1337);
  Network& net = *model.net;
  if (dev == Device::Cuda) return run_bench_cuda(a, vol, model);
  const bool training = a.what == "train";
  if (!training) net.set_inference_precision(parse_precision(a.precision));
  const Precision train_precision = training ? resolve_training_precision(a.precision, net) : Precision::FP32;
  std::vector<double> times;
  double phases[3] = {0, 0, 0};
  std::array<CpuTrainer::Phase, 3> phase_names{};
  auto t0 = std::chrono::steady_clock::now();
  Progress bar(std::string("bench ") + a.what, a.seconds, false);
  if (training) {
    TrainOptions to{a.batch, 1337};
    to.precision = train_precision;
    CpuTrainer tr(net, std::make_shared<InCoreSampler>(vol), to);
    phase_names = tr.phases();
    for (int w = 0; w < 2; ++w) tr.step();  // warm-up: page-in, caches
    t0 = std::chrono::steady_clock::now();
    std::vector<double> ph[3];
    while (seconds_since(t0) < a.seconds || times.size() < 3) {
      auto s0 = std::chrono::steady_clock::now();
      tr.step();
      times.push_back(seconds_since(s0));
      for (int p = 0; p < 3; ++p) ph[p].push_back(tr.phase_seconds[p]);
      bar.update(seconds_since(t0));
    }
    for (int p = 0; p < 3; ++p) phases[p] = median(ph[p]);
  } else {
    ModelQuery query(model, Device::Cpu);
    std::vector<float> coords(3 * a.batch), out(a.batch);
    Pcg32 rng(7);
    for (auto& c : coords) c = rng.next_float();
    query.points(coords.data(), a.batch, out.data());
    t0 = std::chrono::steady_clock::now();
    while (seconds_since(t0) < a.seconds || times.size() < 3) {
      auto s0 = std::chrono::steady_clock::now();
      query.points(coords.data(), a.batch, out.data());
      times.push_back(seconds_since(s0));
      bar.update(seconds_since(t0));
    }
  }
  bar.finish();
  const double med = median(times);
  const double sps = a.batch / med;
  const double flops = net.flops_forward_per_sample() * (training ? 3.0 : 1.0);
  const double mlp_only = mlp_gflops(net, training, train_precision, std::min(3.0, std::max(0.5, a.seconds / 4)));
  std::printf("%s %s%s: %.3f M samples/s (median of %zu batches of %lld, %.2f ms each; min %.2f, max %.2f)\n",
              a.what.c_str(), a.config.c_str(),
              (training ? train_precision : net.inference_precision()) == Precision::BF16 ? " (bf16)" : "",
              sps / 1e6, times.size(), (long long)a.batch, med * 1e3,
              *std::min_element(times.begin(), times.end()) * 1e3, *std::max_element(times.begin(), times.end()) * 1e3);
  std::printf("MLP FLOPs: %.1f kFLOP/sample -> %.1f GFLOP/s end to end; MLP kernels alone: %.1f GFLOP/s on %d threads (%s)\n",
              flops / 1e3, flops * sps / 1e9, mlp_only, num_threads(), kernels::simd_target_name());
  if (training) {
    std::string line;
    for (int p = 0; p < 3; ++p)
      line += fmt::format("{}{} {:.2f}", p ? ", " : "", phase_names[p].name, phases[p] * 1e3);
    std::printf("phases (median ms): %s\n", line.c_str());
  }
  Json report = {{"mode", a.what},
                 {"device", "cpu"},
                 {"config", a.config},
                 {"samples_per_second", sps},
                 {"batch", a.batch},
                 {"batches", times.size()},
                 {"ms_median", med * 1e3},
                 {"ms_min", *std::min_element(times.begin(), times.end()) * 1e3},
                 {"ms_max", *std::max_element(times.begin(), times.end()) * 1e3},
                 {"mlp_flops_per_sample", flops},
                 {"gflops_end_to_end", flops * sps / 1e9},
                 {"mlp_gflops", mlp_only},
                 {"threads", num_threads()},
                 {"simd", kernels::simd_target_name()},
                 {"precision", precision_name(training ? train_precision : net.inference_precision())},
                 {"n_params", net.n_params()}};
  if (training) {
    Json ph = Json::object();
    for (int p = 0; p < 3; ++p) ph[phase_names[p].key] = phases[p] * 1e3;
    report["phase_ms"] = ph;
  }
  write_report(a.report, report);
}

}  // namespace

void add_bench(CLI::App& app) {
  CLI::App* bench = app.add_subcommand("bench", "measure training, inference or rendering throughput");
  bench->require_subcommand(1);
  for (const char* what : {"train", "infer"}) {
    auto a = std::make_shared<BenchArgs>();
    a->what = what;
    CLI::App* c = bench->add_subcommand(
        what, std::string(what) == "train" ? "training throughput on a volume" : "batched inference throughput");
    c->add_option("volume", a->volume, "volume to sample")->required();
    c->add_option("--config", a->config, "preset or config file")->capture_default_str();
    c->add_option("--seconds", a->seconds, "timed duration")->capture_default_str();
    c->add_option("--batch", a->batch, "samples per batch")->capture_default_str();
    c->add_option("--threads", a->threads, "CPU threads (default: all cores)");
    c->add_option("--report", a->report, "write a JSON report");
    add_device_option(c, a->device);
    if (std::string(what) == "infer") add_precision_option(c, a->precision);
    else add_training_precision_option(c, a->precision);
    c->add_option("--mlp", a->mlp, "cuda: MLP implementation, auto, fused or cublas")
        ->check(CLI::IsMember({"auto", "fused", "cublas"}))
        ->capture_default_str();
    a->vol.add(c);
    c->callback([a]() { run_bench(*a); });
  }
  add_bench_render(*bench);
}

}  // namespace vnr::cli
