// vnr render: renders a model or a volume to an image (paper "Rendering"; compat.md B.5-B.10).
#include <cstdio>
#include "cli.h"
#include "render_setup.h"
#include "vnr/core/error.h"
#include "vnr/core/fileio.h"
#include "vnr/core/parallel.h"
#include "vnr/core/progress.h"
#include "vnr/render/renderer.h"

namespace vnr::cli {

namespace {

Vec3f parse_vec3(const std::string& s, const char* what) {
  float v[3];
  char tail;
  if (std::sscanf(s.c_str(), "%f,%f,%f%c", &v[0], &v[1], &v[2], &tail) != 3 || !std::isfinite(v[0]) ||
      !std::isfinite(v[1]) || !std::isfinite(v[2]))
    fail("{} expects X,Y,Z (three numbers), got '{}'", what, s);
  return Vec3f{v[0], v[1], v[2]};
}

}  // namespace

void parse_size(const std::string& s, int* w, int* h) {
  char tail;
  if (std::sscanf(s.c_str(), "%dx%d%c", w, h, &tail) != 2 || *w < 1 || *h < 1 || *w > 32768 || *h > 32768)
    fail("--size expects WxH (positive, at most 32768), got '{}'", s);
}

void RenderArgs::add(CLI::App* c) {
  c->add_option("--scene", scene, "scene file: instantvnr scene JSON or vnr scene JSON (camera, TF, light)");
  c->add_option("--tf", tf, "transfer function: a preset (" + [] {
    std::string l;
    for (auto& n : tf_preset_names()) l += (l.empty() ? "" : ", ") + n;
    return l;
  }() + ") or a JSON file");
  c->add_option("--mode", mode, "raymarch|shadow|pathtrace")->capture_default_str();
  c->add_option("--strategy", strategy, "streaming|inshader")->capture_default_str();
  c->add_option("--macrocells", macrocells,
                "grid|online|off (default: online for a vnr-trained model, grid for a volume)");
  c->add_option("--macrocell-size", macrocell_size, "voxels per macro-cell for --macrocells grid")->capture_default_str();
  c->add_option("--size", size, "image size WxH")->capture_default_str();
  c->add_option("--step", step, "base ray-marching step in voxels (s1)")->capture_default_str();
  c->add_option("--step-max", step_max, "largest adaptive step s2 in voxels (default 16 x step; = step: uniform)");
  c->add_option("--seed", seed, "seed of the jitter and path-tracing random numbers")->capture_default_str();
  c->add_option("--samples-per-iteration,-K", k,
                 fmt::format("streaming: samples per live ray per iteration (default {}, tuned)", kDefaultSamplesPerIteration));
  c->add_option("--orbit", orbit, "camera AZIMUTH[,ELEVATION] in degrees around the volume (when no scene camera)");
  c->add_option("--fovy", fovy, "vertical field of view in degrees for --orbit")->capture_default_str();
  c->add_option("--eye", eye, "camera position X,Y,Z (world = voxel units, box [0, dims])");
  c->add_option("--center", center, "camera look-at point X,Y,Z");
  c->add_option("--up", up, "camera up vector X,Y,Z")->capture_default_str();
  c->add_option("--light", light, "direction toward the directional light X,Y,Z");
  c->add_option("--background", background, "background colour R,G,B");
  c->add_option("--density", density, "path tracing: extinction per voxel = opacity x density")->capture_default_str();
  c->add_option("--ray-packets", ray_packets,
                "on|off: in-shader ray marching of a volume runs rays in SIMD packets (off: the per-ray "
                "reference loop; same image)")
      ->check(CLI::IsMember({"on", "off"}))
      ->capture_default_str();
  c->add_flag("--shade", shade, "gradient (Phong, headlight) shading for ray marching");
  c->add_option("--volume", volume, "ground-truth volume of a model (for --macrocells grid)");
  c->add_option("--threads", threads, "CPU threads (default: all cores)");
  add_device_option(c, device);
  add_precision_option(c, precision);
  c->add_option("--mlp", mlp, "cuda: MLP of streaming inference, auto, fused or cublas")
      ->check(CLI::IsMember({"auto", "fused", "cublas"}))
      ->capture_default_str();
}

namespace {
// --device: auto renders on a visible GPU when the field can go there (a grid, or a network with a grid
// encoding and ReLU layers), else on the CPU with a note; an explicit cuda fails with one line.
Device choose_render_device(const RenderArgs& a, const RenderSource& src) {
  const Device asked = cuda::resolve_device(a.device);
  if (asked == Device::Cpu) return Device::Cpu;
  const std::string why_not = src.model ? cuda::unsupported_reason(*src.model->net) : "";
  if (why_not.empty()) return Device::Cuda;
  if (a.device == "cuda") fail("{}; use --device cpu", why_not);
  std::fprintf(stderr, "note: rendering on the CPU: %s\n", why_not.c_str());
  return Device::Cpu;
}
}  // namespace

RenderSetup make_render_setup(const RenderArgs& a, const RenderSource& src) {
  RenderSetup r;
  RenderOptions& o = r.options;
  o.mode = parse_render_mode(a.mode);
  o.strategy = parse_render_strategy(a.strategy);
  parse_size(a.size, &o.width, &o.height);
  o.step = a.step;
  o.step_max = a.step_max;
  o.seed = a.seed;
  o.samples_per_iteration = a.k > 0 ? a.k : kDefaultSamplesPerIteration;
  o.shade = a.shade;
  o.ray_packets = a.ray_packets == "on";
  o.density_scale = a.density;
  Scene scene = src.scene;
  if (!a.scene.empty()) scene = load_scene(a.scene);
  // transfer function: --tf, else the scene's, else the default preset
  if (!a.tf.empty()) r.tf = load_transfer_function(a.tf);
  else if (scene.tf) r.tf = *scene.tf;
  else r.tf = tf_preset("ramp");
  // camera: explicit --eye/--center, else --orbit, else the scene's, else the default orbit
  if (!a.eye.empty() || !a.center.empty()) {
    if (a.eye.empty() || a.center.empty()) fail("--eye and --center go together");
    r.camera = Camera{parse_vec3(a.eye, "--eye"), parse_vec3(a.center, "--center"), parse_vec3(a.up, "--up"), a.fovy};
  } else if (!a.orbit.empty() || !scene.camera) {
    float az = 0, el = 0;
    if (!a.orbit.empty()) {
      char tail;
      int got = std::sscanf(a.orbit.c_str(), "%f,%f%c", &az, &el, &tail);
      if (got < 1 || got > 2 || !std::isfinite(az) || !std::isfinite(el) || el <= -90 || el >= 90)
        fail("--orbit expects AZIMUTH[,ELEVATION] in degrees (elevation in (-90, 90)), got '{}'", a.orbit);
    }
    r.camera = orbit_camera(src.box, az, el, a.fovy);
    r.orbit_elevation = el;
  } else {
    r.camera = *scene.camera;
  }
  if (scene.light) o.light = *scene.light;
  if (!a.light.empty()) o.light.direction = parse_vec3(a.light, "--light");
  if (scene.background) o.background = *scene.background;
  if (!a.background.empty()) o.background = parse_vec3(a.background, "--background");
  r.macrocell_mode = a.macrocells.empty() ? default_macrocell_mode(src) : parse_macrocell_mode(a.macrocells);
  r.device = choose_render_device(a, src);
  r.mlp = cuda::parse_mlp_path(a.mlp);
  if (a.macrocell_size < 1) fail("--macrocell-size must be at least 1, got {}", a.macrocell_size);
  return r;
}

void add_render(CLI::App& app) {
  struct Args {
    std::string input, output, report, reference;
    int spp = 1;
    bool quiet = false;
    RenderArgs r;
    VolumeArgs vol;
  };
  auto a = std::make_shared<Args>();
  CLI::App* c = app.add_subcommand("render", "render a model or a volume to an image (PNG or PFM)");
  c->add_option("input", a->input, "model (.vnr, instantvnr BSON) or volume (sidecar, scene, NRRD, raw)")->required();
  c->add_option("-o,--output", a->output, "image file: .png (8-bit) or .pfm (float)")->required();
  c->add_option("--spp", a->spp, "frames accumulated (samples per pixel)")->capture_default_str();
  c->add_option("--report", a->report, "write a JSON report");
  c->add_option("--reference", a->reference, "compare with this image (PNG or PFM): PSNR and SSIM");
  c->add_flag("-q,--quiet", a->quiet, "no progress output");
  a->r.add(c);
  a->vol.add(c);
  c->callback([a]() {
    set_num_threads(a->r.threads);
    const std::string ext = extension_of(a->output);
    if (ext != ".png" && ext != ".pfm") fail("-o must name a .png or .pfm file, got '{}'", a->output);
    if (a->spp < 1) fail("--spp must be at least 1, got {}", a->spp);
    RenderSource src = open_render_source(a->input, a->r.volume, a->vol, parse_precision(a->r.precision));
    RenderSetup setup = make_render_setup(a->r, src);
    std::optional<Image> reference;
    if (!a->reference.empty()) reference = read_image(a->reference);
    MacroCells mc = make_macrocells(src, setup.macrocell_mode, a->r.macrocell_size, setup.device);
    mc.update(setup.tf);
    std::unique_ptr<FrameRenderer> renderer = make_setup_renderer(setup, src, mc, setup.camera, setup.options);
    RenderStats st;
    Progress bar("render", a->spp, a->quiet || a->spp < 2);
    Image acc(setup.options.width, setup.options.height), frame(setup.options.width, setup.options.height);
    for (int f = 0; f < a->spp; ++f) {
      renderer->render_frame(uint32_t(f), frame, &st);
      accumulate_frame(acc, frame, f);
      bar.update(f + 1, fmt::format("{:.3f} s/frame", st.seconds / st.frames));
    }
    bar.finish();
    write_image(a->output, acc);
    Json report = {{"seconds_per_frame", st.seconds / st.frames},
                   {"frames", st.frames},
                   {"rays", st.rays},
                   {"field_samples", st.field_samples},
                   {"field_samples_per_second", double(st.field_samples) / st.seconds},
                   {"streaming_iterations", st.iterations},
                   {"mode", render_mode_name(setup.options.mode)},
                   {"strategy", render_strategy_name(setup.options.strategy)},
                   {"macrocells", macrocell_mode_name(setup.macrocell_mode)},
                   {"field", src.field->kind()},
                   {"size", {setup.options.width, setup.options.height}},
                   {"threads", num_threads()},
                   {"device", device_name(setup.device)},
                   {"precision", precision_json(src.model ? src.model->net.get() : nullptr, setup.device)},
                   {"host_syncs", st.host_syncs}};
    std::string cmp;
    if (reference) {
      ImageMetrics im = compare_images(acc, *reference);
      report["image_psnr"] = im.psnr;
      report["image_ssim"] = im.ssim;
      cmp = fmt::format(", vs reference: PSNR {:.2f} dB, SSIM {:.4f}", im.psnr, im.ssim);
    }
    if (!a->quiet)
      std::printf("%s: %s %s %s %dx%d, %d frame(s), %.3f s/frame (%.2f frames/s), %.1f M field samples/s%s -> %s\n",
                  src.description.c_str(), device_name(setup.device), render_mode_name(setup.options.mode),
                  render_strategy_name(setup.options.strategy), setup.options.width, setup.options.height, st.frames,
                  st.seconds / st.frames, st.frames / st.seconds, double(st.field_samples) / st.seconds / 1e6,
                  cmp.c_str(), a->output.c_str());
    write_report(a->report, report);
  });
}

}  // namespace vnr::cli
