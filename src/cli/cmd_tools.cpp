// eval, decode, info, synth and convert: each parses its options, calls the library and prints.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include "cli.h"
#include "train_cli.h"
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/threads.h"
#include "vnr/progress.h"
#include "vnr/units.h"
#include "vnr/device.h"
#include "vnr/model.h"
#include "vnr/volume.h"
#include "vnr/volume_writer.h"
#include "vnr/version.h"

namespace vnr::cli {

namespace {

// The line and report keys of an evaluation: whole-volume (in memory or streamed) or from sampled voxels.
void print_evaluation(const FileEvaluation& ev, Json& report) {
  const std::string ratio = format_ratio(ev.compression_ratio);
  if (ev.psnr_ci95) {
    std::printf("PSNR %.2f dB (95%% interval %.2f to %.2f dB, from %lld sampled voxels), max |error| seen %.4g "
                "(%.4g in data units), compression ratio %s, decoded in %.2fs\n",
                ev.psnr, ev.psnr_ci95->first, ev.psnr_ci95->second, (long long)ev.samples, ev.max_abs_error,
                ev.max_abs_error_original, ratio.c_str(), ev.decode_seconds);
  } else {
    std::printf("PSNR %.2f dB", ev.psnr);
    if (ev.ssim) std::printf(", SSIM %.4f", *ev.ssim);
    std::printf(", max |error| %.4g (%.4g in data units), compression ratio %s, decoded in %.2fs\n", ev.max_abs_error,
                ev.max_abs_error_original, ratio.c_str(), ev.decode_seconds);
  }
  report.update({{"psnr", ev.psnr},
                 {"psnr_ci95", ev.psnr_ci95 ? Json{ev.psnr_ci95->first, ev.psnr_ci95->second} : Json(nullptr)},
                 {"ssim", ev.ssim ? Json(*ev.ssim) : Json(nullptr)},
                 {"mse", ev.mse},
                 {"max_abs_error", ev.max_abs_error},
                 {"max_abs_error_original", ev.max_abs_error_original},
                 {"samples", ev.samples},
                 {"decode_seconds", ev.decode_seconds},
                 {"value_range", {ev.value_range.lo, ev.value_range.hi}},
                 {"value_range_source", ev.value_range_source}});
  if (ev.psnr_ci95) report["mse_stderr"] = ev.mse_stderr;
  if (ev.error_bound_original) {
    std::printf("error bound %.4g (data units): %s\n", *ev.error_bound_original,
                ev.bound_holds ? (ev.psnr_ci95 ? "holds at every sampled voxel" : "holds at every voxel") : "VIOLATED");
    report["error_bound"] = {{"max_error", *ev.error_bound_original}, {"holds", ev.bound_holds}};
  }
}

// Progress bars on stderr, one per stage as it starts, and the notes as they arise.
struct EvalProgressBars {
  bool quiet = false;
  std::map<std::string, std::unique_ptr<Progress>> bars;
  FileEvalProgress callbacks() {
    FileEvalProgress p;
    p.update = [this](const std::string& stage, double f) { bar(stage).update(f); };
    p.finished = [this](const std::string& stage) { bar(stage).finish(); };
    p.note = [](const std::string& text) { std::fprintf(stderr, "note: %s\n", text.c_str()); };
    return p;
  }
  Progress& bar(const std::string& stage) {
    std::unique_ptr<Progress>& b = bars[stage];
    if (!b) b = std::make_unique<Progress>(stage, 1.0, quiet);
    return *b;
  }
};

}  // namespace

void add_eval(CLI::App& app) {
  struct Args {
    std::string model, volume, report, memory_budget;
    int threads = 0;
    int64_t sample = 0;
    uint64_t seed = 0;
    bool no_ssim = false, quiet = false;
    std::string device = "auto", precision = "auto";
    VolumeArgs vol;
  };
  auto a = std::make_shared<Args>();
  CLI::App* c = app.add_subcommand("eval", "compare a model with its volume: PSNR, SSIM, max error");
  c->add_option("model", a->model, "model file (.vnr or instantvnr BSON)")->required();
  c->add_option("volume", a->volume, "the ground-truth volume")->required();
  c->add_option("--report", a->report, "write a JSON report");
  c->add_option("--threads", a->threads, "CPU threads (default: all cores)");
  c->add_flag("--no-ssim", a->no_ssim, "skip the 3-D SSIM");
  c->add_option("--sample", a->sample,
                "estimate PSNR (with a 95% interval) from N random voxels, read one by one: any volume size, "
                "uncompressed data only, no SSIM");
  c->add_option("--seed", a->seed, "seed of the --sample voxels")->capture_default_str();
  c->add_option("--memory-budget", a->memory_budget,
                "memory for the volume and the decoded copy, e.g. 8GiB (default: half the available memory); "
                "a larger volume is evaluated in streamed z-slabs");
  c->add_flag("-q,--quiet", a->quiet, "no progress output");
  add_device_option(c, a->device);
  add_precision_option(c, a->precision);
  a->vol.add(c);
  c->callback([a, c]() {
    set_num_threads(a->threads);
    Model m = load_model(a->model);
    set_inference_precision(m, parse_precision(a->precision));
    FileEvalOptions o;
    o.device = cuda::resolve_device(a->device);
    o.with_ssim = !a->no_ssim;
    o.seed = a->seed;
    o.open = a->vol.open();
    o.model_path = a->model;
    if (c->count("--sample") > 0) {
      if (a->sample <= 0) fail("--sample expects a positive number of voxels, got {}", a->sample);
      o.samples = a->sample;
    }
    if (!a->memory_budget.empty()) {
      try {
        o.memory_budget = parse_byte_size(a->memory_budget);
      } catch (const Error& e) {
        fail("--memory-budget: {}", e.what());
      }
    }
    EvalProgressBars bars;
    bars.quiet = a->quiet;
    const FileEvaluation ev = evaluate_model_file(m, a->volume, o, bars.callbacks());
    Json report = {{"method", eval_method_name(ev.plan.method)},
                   {"device", device_name(ev.device)},
                   {"precision", precision_json(&m, ev.device)},
                   {"compression_ratio", ev.compression_ratio},
                   {"model_bytes", ev.model_bytes},
                   {"volume_bytes", ev.volume_bytes}};
    print_evaluation(ev, report);
    if (ev.plan.method == EvalMethod::Sampled) report["seed"] = a->seed;
    write_report(a->report, report);
  });
}

void add_decode(CLI::App& app) {
  struct Args {
    std::string model, output, dims, dtype = "float32", device = "auto", precision = "auto";
    int threads = 0;
    bool quiet = false, force = false;
  };
  auto a = std::make_shared<Args>();
  CLI::App* c = app.add_subcommand("decode", "decode a model to a volume file (raw + JSON sidecar, or NRRD)");
  c->add_option("model", a->model, "model file")->required();
  c->add_option("-o,--output", a->output, "OUT.raw (with OUT.json sidecar) or OUT.nrrd")->required();
  c->add_option("--dims", a->dims, "output resolution X,Y,Z (default: the model's)");
  c->add_option("--dtype", a->dtype, "float32, or 'source' for the original data type")->capture_default_str();
  c->add_option("--threads", a->threads, "CPU threads (default: all cores)");
  c->add_flag("-q,--quiet", a->quiet, "no progress output");
  c->add_flag("--force", a->force, "replace existing output files");
  add_device_option(c, a->device);
  add_precision_option(c, a->precision);
  c->callback([a]() {
    set_num_threads(a->threads);
    check_no_overwrite(volume_output_files(a->output), a->force);
    Model m = load_model(a->model);
    set_inference_precision(m, parse_precision(a->precision));
    ModelQuery query(m, cuda::resolve_device(a->device));
    const Device dev = query.device();
    const Int3 dims = a->dims.empty() ? m.dims : parse_dims(a->dims);
    const DType out_t = a->dtype == "source" ? m.source_dtype : parse_dtype(a->dtype);
    Progress bar("decode", double(dims.z), a->quiet);
    auto t0 = std::chrono::steady_clock::now();
    query.decode_to_file(a->output, dims, out_t, [&](int64_t done, int64_t) { bar.update(double(done)); });
    bar.finish();
    std::printf("decoded %lldx%lldx%lld %s to %s in %.2fs (%s)\n", (long long)dims.x, (long long)dims.y,
                (long long)dims.z, dtype_name(out_t), a->output.c_str(), seconds_since(t0), device_name(dev));
  });
}

namespace {
// What this vnr can run on: the CPU's SIMD target and threads, the CUDA backend and its devices.
void print_system_info(bool json) {
  std::vector<cuda::DeviceInfo> devs = cuda::devices();
  Json jd = Json::array();
  for (const cuda::DeviceInfo& d : devs)
    jd.push_back({{"index", d.index},
                  {"name", d.name},
                  {"compute_capability", fmt::format("{}.{}", d.cc_major, d.cc_minor)},
                  {"memory_bytes", d.memory_bytes},
                  {"multiprocessors", d.sm_count}});
  Json j = {{"version", vnr::version()},
            {"cpu", {{"simd", kernels::simd_target_name()}, {"threads", num_threads()}}},
            {"cuda", {{"built", cuda::built()}, {"devices", jd}}},
            {"default_device", devs.empty() ? "cpu" : "cuda"}};
  if (devs.empty()) j["cuda"]["no_device_reason"] = cuda::no_device_reason();
  if (json) {
    std::printf("%s\n", j.dump(2).c_str());
    return;
  }
  std::printf("vnr %s\n", vnr::version());
  std::printf("cpu: %s, %d threads\n", kernels::simd_target_name(), num_threads());
  std::printf("%s\n", cuda::backend_summary().c_str());
  std::printf("default --device: %s\n", devs.empty() ? "cpu" : "cuda");
}

// `vnr info FILE.h5:/DATASET` (or FILE.nc:VARIABLE, or the file alone: then the error lists its
// volumes): what the volume layer reads from the dataset.
void print_dataset_info(const std::string& path, bool json) {
  const VolumeDesc d = describe_volume_file(path);
  if (json) {
    const Json j = {{"file", d.path},       {"encoding", d.encoding},       {"dataset", d.dataset},
                    {"dims", {d.dims.x, d.dims.y, d.dims.z}}, {"dtype", dtype_name(d.dtype)},
                    {"n_timesteps", d.n_timesteps}};
    std::printf("%s\n", j.dump(2).c_str());
    return;
  }
  std::printf("%s: %s %s, %lldx%lldx%lld %s (x = the last axis), %d timestep%s\n", path.c_str(),
              d.encoding == "hdf5" ? "HDF5 dataset" : "NetCDF variable", d.dataset.c_str(), (long long)d.dims.x,
              (long long)d.dims.y, (long long)d.dims.z, dtype_name(d.dtype), d.n_timesteps, d.n_timesteps == 1 ? "" : "s");
}
}  // namespace

void add_info(CLI::App& app) {
  struct Args {
    std::string model;
    bool json = false;
  };
  auto a = std::make_shared<Args>();
  CLI::App* c = app.add_subcommand("info", "describe a model file, an HDF5/NetCDF volume (FILE.h5:/DATASET, FILE.nc:VARIABLE), or (without one) this vnr's backends and devices");
  c->add_option("model", a->model, "model file, or FILE.h5:/DATASET / FILE.nc:VARIABLE");
  c->add_flag("--json", a->json, "print JSON");
  c->callback([a]() {
    if (a->model.empty()) return print_system_info(a->json);
    if (is_dataset_path(a->model)) return print_dataset_info(a->model, a->json);
    Model m = load_model(a->model);
    const Json j = describe_model(m, a->model);
    const uint64_t bytes = j["model_bytes"].get<uint64_t>();
    if (a->json) {
      std::printf("%s\n", j.dump(2).c_str());
      return;
    }
    const ModelConfig& cfg = model_config(m);
    std::printf("%s: vnr model of a %lldx%lldx%lld %s volume, range [%g, %g]\n", a->model.c_str(),
                (long long)m.dims.x, (long long)m.dims.y, (long long)m.dims.z, dtype_name(m.source_dtype), m.lo, m.hi);
    if (const uint64_t entries = hash_grid_entries(m))
      std::printf("encoding: %s, %u levels x %u features, 2^%u table, base %u (%llu entries)\n",
                  j["config"]["encoding"]["otype"].get<std::string>().c_str(), cfg.encoding.n_levels,
                  cfg.encoding.n_features_per_level, cfg.encoding.log2_hashmap_size, cfg.encoding.base_resolution,
                  (unsigned long long)entries);
    else
      std::printf("encoding: %s\n", j["config"]["encoding"].dump().c_str());
    std::printf("network: %s %u x %u hidden, %s; loss %s\n", cfg.network.fully_fused ? "FullyFusedMLP" : "CutlassMLP",
                cfg.network.n_neurons, cfg.network.n_hidden_layers, activation_name(cfg.network.activation),
                loss_name(cfg.loss));
    std::printf("parameters: %llu (%s in fp16); file %s; compression ratio %s\n",
                (unsigned long long)j["n_params"].get<uint64_t>(), human_bytes(2.0 * j["n_params"].get<double>()).c_str(),
                human_bytes(double(bytes)).c_str(),
                format_ratio(j["compression_ratio"].get<double>()).c_str());
    if (const Json& mc = j["macrocells"]; !mc.is_null())
      std::printf("macro-cells: %lldx%lldx%lld cells of %d voxels (%lld with a value range), recorded while training\n",
                  mc["cells"][0].get<long long>(), mc["cells"][1].get<long long>(), mc["cells"][2].get<long long>(),
                  mc["cell_size"].get<int>(), mc["occupied"].get<long long>());
    else
      std::printf("macro-cells: none stored (vnr render uses --macrocells grid with --volume, or off)\n");
    if (j.contains("error_bound"))
      std::printf("error bound: %.4g (data units) at every voxel of the model's dims; residuals %s, %.2f%% non-zero\n",
                  j["error_bound"]["max_error"].get<double>(),
                  human_bytes(j["error_bound"]["residual_bytes"].get<double>()).c_str(),
                  100.0 * j["error_bound"]["residual_nonzero"].get<double>() / double(m.dims.count()));
    if (m.training.is_object()) std::printf("training: %s\n", m.training.dump().c_str());
    if (j["format"] == "vnr-bricks") print_brick_info(j);
  });
}

void add_synth(CLI::App& app) {
  struct Args {
    std::string kind, dims, output;
    uint64_t seed = 1;
    int timesteps = 0;
    bool force = false, file_list = false;
  };
  auto a = std::make_shared<Args>();
  CLI::App* c = app.add_subcommand("synth", "write a procedural volume (raw + JSON sidecar), streamed");
  c->add_option("kind", a->kind, "marschner-lobb | noise")->required()->check(CLI::IsMember({"marschner-lobb", "noise"}));
  c->add_option("--dims", a->dims, "X,Y,Z")->required();
  c->add_option("-o,--output", a->output, "OUT.json (the raw data goes to OUT.raw)")->required();
  c->add_option("--seed", a->seed, "seed of the noise field")->capture_default_str();
  c->add_option("--timesteps", a->timesteps,
                "write a time series of T timesteps in which the field drifts smoothly (a 4-D sidecar: all frames "
                "in OUT.raw)");
  c->add_flag("--file-list", a->file_list,
              "with --timesteps: one raw file per timestep (OUT_t0000.raw, ...) named by a file-list sidecar");
  c->add_flag("--force", a->force, "replace existing output files");
  c->callback([a]() {
    Int3 d = parse_dims(a->dims);
    if (a->file_list && a->timesteps <= 0) fail("--file-list needs --timesteps T");
    if (a->timesteps < 0) fail("--timesteps must be positive, got {}", a->timesteps);
    auto t0 = std::chrono::steady_clock::now();
    if (a->timesteps > 0) {
      check_no_overwrite(synth_series_output_files(a->output, a->timesteps, a->file_list), a->force);
      synth_series(a->kind, d, a->timesteps, a->output, a->seed, a->file_list);
      std::printf("wrote %s (%lldx%lldx%lld float32, %d timesteps%s) in %.2fs\n", a->output.c_str(), (long long)d.x,
                  (long long)d.y, (long long)d.z, a->timesteps, a->file_list ? ", one file each" : "",
                  seconds_since(t0));
      return;
    }
    check_no_overwrite(synth_output_files(a->output), a->force);
    synth_volume(a->kind, d, a->output, a->seed);
    std::printf("wrote %s (%lldx%lldx%lld float32) in %.2fs\n", a->output.c_str(), (long long)d.x, (long long)d.y,
                (long long)d.z, seconds_since(t0));
  });
}

void add_convert(CLI::App& app) {
  struct Args {
    std::string in, out;
  };
  auto a = std::make_shared<Args>();
  CLI::App* c = app.add_subcommand("convert", "convert between .vnr and instantvnr's BSON model format");
  c->add_option("input", a->in, "model file (.vnr or instantvnr BSON)")->required();
  c->add_option("-o,--output", a->out, "output (.vnr, or .json/.bson for instantvnr)")->required();
  c->callback([a]() {
    Model m = load_model(a->in);
    save_model(a->out, m);
    std::printf("wrote %s\n", a->out.c_str());
  });
}

}  // namespace vnr::cli
