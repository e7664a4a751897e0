// eval, decode, info, synth and convert.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include "cli.h"
#include "vnr/core/error.h"
#include "vnr/core/fileio.h"
#include "vnr/core/parallel.h"
#include "vnr/core/progress.h"
#include "vnr/train/model_io.h"
#include "vnr/volume/writer.h"

namespace vnr::cli {

void add_eval(CLI::App& app) {
  struct Args {
    std::string model, volume, report;
    int threads = 0;
    bool no_ssim = false;
    VolumeArgs vol;
  };
  auto a = std::make_shared<Args>();
  CLI::App* c = app.add_subcommand("eval", "compare a model with its volume: PSNR, SSIM, max error");
  c->add_option("model", a->model, "model file (.vnr or instantvnr BSON)")->required();
  c->add_option("volume", a->volume, "the ground-truth volume")->required();
  c->add_option("--report", a->report, "write a JSON report");
  c->add_option("--threads", a->threads, "CPU threads (default: all cores)");
  c->add_flag("--no-ssim", a->no_ssim, "skip the 3-D SSIM");
  a->vol.add(c);
  c->callback([a]() {
    set_num_threads(a->threads);
    Model m = load_model(a->model);
    RawOptions raw = a->vol.raw();
    Volume vol = load_volume(describe_volume(a->volume, raw), a->vol.load());
    if (!(vol.dims == m.dims))
      std::fprintf(stderr, "note: model was trained on %lldx%lldx%lld, evaluating at %lldx%lldx%lld\n",
                   (long long)m.dims.x, (long long)m.dims.y, (long long)m.dims.z, (long long)vol.dims.x,
                   (long long)vol.dims.y, (long long)vol.dims.z);
    EvalResult ev = evaluate(*m.net, vol, !a->no_ssim);
    uint64_t model_bytes = file_size(a->model);
    double ratio = double(vol.source_bytes()) / double(model_bytes);
    std::printf("PSNR %.2f dB", ev.psnr);
    if (!a->no_ssim) std::printf(", SSIM %.4f", ev.ssim);
    std::printf(", max |error| %.4g (%.4g in data units), compression ratio %.2f, decoded in %.2fs\n",
                ev.max_abs_error, ev.max_abs_error_original, ratio, ev.decode_seconds);
    write_report(a->report, {{"psnr", ev.psnr},
                             {"ssim", a->no_ssim ? Json(nullptr) : Json(ev.ssim)},
                             {"mse", ev.mse},
                             {"max_abs_error", ev.max_abs_error},
                             {"max_abs_error_original", ev.max_abs_error_original},
                             {"compression_ratio", ratio},
                             {"model_bytes", model_bytes},
                             {"volume_bytes", vol.source_bytes()},
                             {"decode_seconds", ev.decode_seconds}});
  });
}

void add_decode(CLI::App& app) {
  struct Args {
    std::string model, output, dims, dtype = "float32";
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
  c->callback([a]() {
    set_num_threads(a->threads);
    check_no_overwrite(volume_output_files(a->output), a->force);
    Model m = load_model(a->model);
    Int3 dims = a->dims.empty() ? m.dims : parse_dims(a->dims);
    DType out_t = a->dtype == "source" ? m.source_dtype : parse_dtype(a->dtype);
    // Slabs of ~16 M voxels: memory stays bounded whatever the output size.
    const int64_t slab = std::max<int64_t>(1, (int64_t(1) << 24) / std::max<int64_t>(1, dims.x * dims.y));
    // Voxel size relative to the model's grid (model files carry no physical spacing).
    Vec3f spacing{float(double(m.dims.x) / dims.x), float(double(m.dims.y) / dims.y), float(double(m.dims.z) / dims.z)};
    VolumeWriter w(a->output, dims, out_t, spacing, std::make_pair(m.lo, m.hi));
    std::vector<float> buf(size_t(dims.x * dims.y * std::min<int64_t>(slab, dims.z)));
    Progress bar("decode", double(dims.z), a->quiet);
    auto t0 = std::chrono::steady_clock::now();
    const double span = m.hi - m.lo;
    for (int64_t z0 = 0; z0 < dims.z; z0 += slab) {
      int64_t z1 = std::min(dims.z, z0 + slab);
      decode_slices(*m.net, dims, z0, z1, buf.data());
      const size_t cnt = size_t(dims.x * dims.y * (z1 - z0));
      for (size_t i = 0; i < cnt; ++i) buf[i] = float(m.lo + double(buf[i]) * span);
      w.write_slices(buf.data(), z1 - z0);
      bar.update(double(z1));
    }
    w.commit();
    bar.finish();
    std::printf("decoded %lldx%lldx%lld %s to %s in %.2fs\n", (long long)dims.x, (long long)dims.y,
                (long long)dims.z, dtype_name(out_t), a->output.c_str(), seconds_since(t0));
  });
}

void add_info(CLI::App& app) {
  struct Args {
    std::string model;
    bool json = false;
  };
  auto a = std::make_shared<Args>();
  CLI::App* c = app.add_subcommand("info", "describe a model file");
  c->add_option("model", a->model, "model file")->required();
  c->add_flag("--json", a->json, "print JSON");
  c->callback([a]() {
    Model m = load_model(a->model);
    const Network& n = *m.net;
    uint64_t bytes = file_size(a->model);
    double vol_bytes = double(m.dims.count()) * dtype_size(m.source_dtype);
    Json j = {{"file", a->model},
              {"format", is_instantvnr_path(a->model) ? "instantvnr-bson" : "vnr"},
              {"dims", {m.dims.x, m.dims.y, m.dims.z}},
              {"dtype", dtype_name(m.source_dtype)},
              {"value_range", {m.lo, m.hi}},
              {"n_params", n.n_params()},
              {"n_mlp_params", n.mlp().n_params},
              {"n_grid_params", n.grid_params()},
              {"model_bytes", bytes},
              {"volume_bytes", uint64_t(vol_bytes)},
              {"compression_ratio", vol_bytes / double(bytes)},
              {"config", n.config_json()},
              {"training", m.training}};
    if (a->json) {
      std::printf("%s\n", j.dump(2).c_str());
      return;
    }
    const ModelConfig& cfg = n.config();
    std::printf("%s: vnr model of a %lldx%lldx%lld %s volume, range [%g, %g]\n", a->model.c_str(),
                (long long)m.dims.x, (long long)m.dims.y, (long long)m.dims.z, dtype_name(m.source_dtype), m.lo, m.hi);
    if (n.has_grid())
      std::printf("encoding: %s, %u levels x %u features, 2^%u table, base %u (%llu entries)\n",
                  j["config"]["encoding"]["otype"].get<std::string>().c_str(), cfg.encoding.n_levels,
                  cfg.encoding.n_features_per_level, cfg.encoding.log2_hashmap_size, cfg.encoding.base_resolution,
                  (unsigned long long)n.grid().n_entries);
    else
      std::printf("encoding: %s\n", j["config"]["encoding"].dump().c_str());
    std::printf("network: %s %u x %u hidden, %s; loss %s\n", cfg.network.fully_fused ? "FullyFusedMLP" : "CutlassMLP",
                cfg.network.n_neurons, cfg.network.n_hidden_layers, activation_name(cfg.network.activation),
                loss_name(cfg.loss));
    std::printf("parameters: %llu (%s in fp16); file %s; compression ratio %.2f\n",
                (unsigned long long)n.n_params(), human_bytes(2.0 * n.n_params()).c_str(), human_bytes(double(bytes)).c_str(),
                vol_bytes / double(bytes));
    if (m.training.is_object()) std::printf("training: %s\n", m.training.dump().c_str());
  });
}

void add_synth(CLI::App& app) {
  struct Args {
    std::string kind, dims, output;
    uint64_t seed = 1;
    bool force = false;
  };
  auto a = std::make_shared<Args>();
  CLI::App* c = app.add_subcommand("synth", "write a procedural volume (raw + JSON sidecar), streamed");
  c->add_option("kind", a->kind, "marschner-lobb | noise")->required()->check(CLI::IsMember({"marschner-lobb", "noise"}));
  c->add_option("--dims", a->dims, "X,Y,Z")->required();
  c->add_option("-o,--output", a->output, "OUT.json (the raw data goes to OUT.raw)")->required();
  c->add_option("--seed", a->seed, "seed of the noise field")->capture_default_str();
  c->add_flag("--force", a->force, "replace existing output files");
  c->callback([a]() {
    Int3 d = parse_dims(a->dims);
    check_no_overwrite(synth_output_files(a->output), a->force);
    auto t0 = std::chrono::steady_clock::now();
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
