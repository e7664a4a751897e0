// vnr render: renders a model or a volume to an image (paper "Rendering"; docs/semantics.md B.5-B.10).
#include <chrono>
#include <cmath>
#include <cstdio>
#include "cli.h"
#include "render_setup.h"
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/threads.h"
#include "vnr/progress.h"
#include "vnr/units.h"

namespace vnr::cli {

void parse_size(const std::string& s, int* w, int* h, const char* option) {
  char tail;
  if (std::sscanf(s.c_str(), "%dx%d%c", w, h, &tail) != 2 || *w < 1 || *h < 1 || *w > 32768 || *h > 32768)
    fail("{} expects WxH (positive, at most 32768), got '{}'", option, s);
}

namespace {

Vec3f parse_vec3(const std::string& s, const char* what) {
  float v[3];
  char tail;
  if (std::sscanf(s.c_str(), "%f,%f,%f%c", &v[0], &v[1], &v[2], &tail) != 3 || !std::isfinite(v[0]) ||
      !std::isfinite(v[1]) || !std::isfinite(v[2]))
    fail("{} expects X,Y,Z (three numbers), got '{}'", what, s);
  return Vec3f{v[0], v[1], v[2]};
}

std::string vec3_text(const Vec3f& v) { return fmt::format("{},{},{}", v.x, v.y, v.z); }

}  // namespace

void RenderArgs::add(CLI::App* c) {
  RenderSettings* r = &s;  // the callbacks write into it; RenderArgs lives in the command's shared Args
  c->add_option("--scene", r->scene, "scene file: instantvnr scene JSON or vnr scene JSON (camera, TF, light)");
  c->add_option("--tf", r->tf, "transfer function: a preset (" + [] {
    std::string l;
    for (auto& n : tf_preset_names()) l += (l.empty() ? "" : ", ") + n;
    return l;
  }() + "), a JSON file or JSON text");
  c->add_option("--mode", r->mode, "raymarch|shadow|pathtrace")->capture_default_str();
  c->add_option("--strategy", r->strategy,
                "auto|cache|streaming|inshader: cache = a model's bricks decoded at the level of detail the view "
                "needs and ray marched as a grid (on the GPU from a copy in GPU memory; docs/RENDERING.md), streaming "
                "and inshader query the field for every sample (the same image); auto = the cache for a model when "
                "frames are accumulated, then the faster of the two for the field, device and mode")
      ->capture_default_str();
  c->add_option_function<std::string>(
       "--cache-budget", [r](const std::string& v) { r->cache_budget = parse_cache_budget(v); },
       "memory of the brick cache's decoded bricks, e.g. 512MiB (auto: a quarter of the available memory, at most "
       "4 GiB)")
      ->default_str("auto");
  c->add_option_function<std::string>(
      "--cache-dims", [r](const std::string& v) { r->cache_dims = parse_dims(v, "--cache-dims"); },
      "X,Y,Z: the voxels the cache decodes a model at (default: the model's dims; any size, e.g. 4096,4096,4096: "
      "only the bricks a view needs are decoded)");
  c->add_option("--macrocells", r->macrocells, "grid|online|off (default: online for a vnr-trained model, grid for a volume)");
  c->add_option("--macrocell-size", r->macrocell_size, "voxels per macro-cell for --macrocells grid")->capture_default_str();
  c->add_option_function<std::string>(
       "--size", [r](const std::string& v) { parse_size(v, &r->width, &r->height); }, "image size WxH")
      ->default_str(fmt::format("{}x{}", s.width, s.height));
  c->add_option("--step", r->step, "base ray-marching step in voxels (s1)")->capture_default_str();
  c->add_option("--step-max", r->step_max, "largest adaptive step s2 in voxels (default 16 x step; = step: uniform)");
  c->add_option("--seed", r->seed, "seed of the jitter and path-tracing random numbers")->capture_default_str();
  c->add_option("--samples-per-iteration,-K", r->samples_per_iteration,
                fmt::format("streaming: samples per live ray per iteration (default {}, tuned)", kDefaultSamplesPerIteration));
  c->add_option_function<std::string>(
      "--orbit",
      [r](const std::string& v) {
        float az = 0, el = 0;
        char tail;
        const int got = std::sscanf(v.c_str(), "%f,%f%c", &az, &el, &tail);
        if (got < 1 || got > 2) fail("--orbit expects AZIMUTH[,ELEVATION] in degrees, got '{}'", v);
        r->orbit = std::make_pair(az, el);
      },
      "camera AZIMUTH[,ELEVATION] in degrees around the volume (when no scene camera)");
  c->add_option("--fovy", r->fovy, "vertical field of view in degrees for --orbit")->capture_default_str();
  c->add_option_function<std::string>(
      "--eye", [r](const std::string& v) { r->eye = parse_vec3(v, "--eye"); },
      "camera position X,Y,Z (world = voxel units, box [0, dims])");
  c->add_option_function<std::string>(
      "--center", [r](const std::string& v) { r->center = parse_vec3(v, "--center"); }, "camera look-at point X,Y,Z");
  c->add_option_function<std::string>(
       "--up", [r](const std::string& v) { r->up = parse_vec3(v, "--up"); }, "camera up vector X,Y,Z")
      ->default_str(vec3_text(s.up));
  c->add_option_function<std::string>(
      "--light", [r](const std::string& v) { r->light = parse_vec3(v, "--light"); },
      "direction toward the directional light X,Y,Z");
  c->add_option_function<std::string>(
      "--background", [r](const std::string& v) { r->background = parse_vec3(v, "--background"); },
      "background colour R,G,B");
  c->add_option("--density", r->density, "path tracing: extinction per voxel = opacity x density")->capture_default_str();
  c->add_option_function<std::string>(
       "--ray-packets", [r](const std::string& v) { r->ray_packets = v == "on"; },
       "on|off: in-shader ray marching of a volume runs rays in SIMD packets (off: the per-ray reference loop; "
       "same image)")
      ->check(CLI::IsMember({"on", "off"}))
      ->default_str(s.ray_packets ? "on" : "off");
  c->add_flag("--shade", r->shade, "gradient (Phong, headlight) shading for ray marching");
  c->add_option("--volume", volume, "ground-truth volume of a model (for --macrocells grid)");
  c->add_option("--threads", threads, "CPU threads (default: all cores)");
  add_device_option(c, r->device);
  add_precision_option(c, r->precision);
  c->add_option("--mlp", r->mlp, "cuda: MLP of streaming inference, auto, fused or cublas")
      ->check(CLI::IsMember({"auto", "fused", "cublas"}))
      ->capture_default_str();
}

void add_render(CLI::App& app) {
  struct Args {
    std::string input, output, report, reference;
    std::string spp = "auto";
    bool quiet = false;
    RenderArgs r;
    VolumeArgs vol;
  };
  auto a = std::make_shared<Args>();
  CLI::App* c = app.add_subcommand("render", "render a model or a volume to an image (PNG or PFM)");
  c->add_option("input", a->input, "model (.vnr, instantvnr BSON) or volume (sidecar, scene, NRRD, raw)")->required();
  c->add_option("-o,--output", a->output, "image file: .png (8-bit) or .pfm (float)")->required();
  c->add_option("--spp", a->spp,
                "frames accumulated (samples per pixel), or auto: until the image's noise (the RMS standard "
                "error of its pixels, estimated from the frames) is at most --noise")
      ->capture_default_str();
  c->add_option("--noise", a->r.s.noise, "--spp auto: the noise to reach, in [0, 1] units (one 8-bit step)")
      ->capture_default_str();
  c->add_option("--max-spp", a->r.s.max_spp, "--spp auto: at most this many frames")->capture_default_str();
  c->add_option("--report", a->report, "write a JSON report");
  c->add_option("--reference", a->reference, "compare with this image (PNG or PFM): PSNR and SSIM");
  c->add_flag("-q,--quiet", a->quiet, "no progress output");
  a->r.add(c);
  a->vol.add(c);
  c->callback([a]() {
    set_num_threads(a->r.threads);
    const std::string ext = extension_of(a->output);
    if (ext != ".png" && ext != ".pfm") fail("-o must name a .png or .pfm file, got '{}'", a->output);
    int spp = 0;  // 0: auto
    if (a->spp != "auto") {
      size_t used = 0;
      try {
        spp = std::stoi(a->spp, &used);
      } catch (const std::exception&) {
        used = 0;
      }
      if (used != a->spp.size() || spp < 1) fail("--spp must be auto or at least 1, got '{}'", a->spp);
    }
    a->r.s.spp = spp;
    CliRender cr = open_cli_render(a->input, a->r, a->vol);
    Renderer& r = *cr.renderer;
    std::optional<Image> reference;
    if (!a->reference.empty()) reference = read_image(a->reference);
    r.prepare();
    const auto t_cache = std::chrono::steady_clock::now();
    {  // the view's bricks decoded before accumulating: every frame reads the cache
      Progress warm("cache", 1, a->quiet);
      r.warm_cache([&](int64_t done, int64_t total) { warm.update(double(done) / double(total), fmt::format("{} of {} bricks", done, total)); });
      if (r.cache()) warm.finish();
    }
    const double cache_seconds = seconds_since(t_cache);
    if (reference && (reference->width != r.options().width || reference->height != r.options().height))
      fail("the --reference image '{}' has size {}x{}, the render is {}x{}", a->reference, reference->width,
           reference->height, r.options().width, r.options().height);
    RenderStats st;
    const Convergence converge{a->r.s.noise, Convergence{}.min_frames, a->r.s.max_spp};
    Progress bar("render", spp ? spp : converge.max_frames, a->quiet || spp == 1);
    if (spp) {
      for (int f = 0; f < spp; ++f) {
        r.render_frame(&st);
        bar.update(f + 1, fmt::format("{:.3f} s/frame", st.seconds / st.frames));
      }
    } else {
      r.render_until_converged(converge, &st, [&](int f, double noise) {
        bar.update(f, fmt::format("{:.3f} s/frame, noise {:.5f}", st.seconds / st.frames, noise));
      });
    }
    bar.finish();
    r.save(a->output);
    const RenderOptions& o = r.options();
    Json report = {{"seconds_per_frame", st.seconds / st.frames},
                   {"frames", st.frames},
                   {"rays", st.rays},
                   {"field_samples", st.field_samples},
                   {"field_samples_per_second", double(st.field_samples) / st.seconds},
                   {"streaming_iterations", st.iterations},
                   {"mode", render_mode_name(o.mode)},
                   {"strategy", render_strategy_name(o.strategy)},
                   {"macrocells", macrocell_mode_name(r.macrocell_mode())},
                   {"field", r.field_kind()},
                   {"size", {o.width, o.height}},
                   {"threads", num_threads()},
                   {"device", device_name(r.device())},
                   {"precision", precision_json(r.model(), r.device())},
                   {"host_syncs", st.host_syncs},
                   {"spp", spp ? Json(spp) : Json("auto")},
                   {"noise", r.frames() > 1 ? Json(r.noise()) : Json(nullptr)}};
    std::string cached;
    if (r.cache()) {
      const BrickCacheStats cs = r.cache_stats();
      report["cache"] = {{"warm_seconds", cache_seconds}, {"bricks_decoded", cs.decoded}, {"bricks_resident", cs.resident},
                         {"pool_bytes", cs.pool_bytes}, {"budget_bytes", cs.budget_bytes}, {"levels", cs.levels}};
      cached = fmt::format(" from a brick cache ({} bricks, {}, warmed in {:.2f} s)", cs.resident,
                           human_bytes(double(cs.pool_bytes)), cache_seconds);
    }
    std::string cmp;
    if (reference) {
      ImageMetrics im = compare_images(r.image(), *reference);
      report["image_psnr"] = im.psnr;
      report["image_ssim"] = im.ssim;
      cmp = fmt::format(", vs reference: PSNR {:.2f} dB, SSIM {:.4f}", im.psnr, im.ssim);
    }
    if (!a->quiet)
      std::printf("%s: %s %s %s%s %dx%d, %d frame(s)%s, %.3f s/frame (%.2f frames/s), %.1f M field samples/s%s -> %s\n",
                  cr.input->description.c_str(), device_name(r.device()), render_mode_name(o.mode),
                  render_strategy_name(o.strategy), cached.c_str(), o.width, o.height, st.frames,
                  r.frames() > 1 ? fmt::format(" (noise {:.5f})", r.noise()).c_str() : "",
                  st.seconds / st.frames, st.frames / st.seconds, double(st.field_samples) / st.seconds / 1e6,
                  cmp.c_str(), a->output.c_str());
    write_report(a->report, report);
  });
}

}  // namespace vnr::cli
