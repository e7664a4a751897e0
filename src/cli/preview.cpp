#include "preview.h"
#include "cli.h"
#include "vnr/error.h"
#include "vnr/renderer.h"

namespace vnr::cli {

void PreviewArgs::add(CLI::App* c) {
  c->add_option("--preview-every", every, "render a preview of the model every N training steps (needs --preview-dir)")
      ->each([this](const std::string&) { every_set = true; });
  c->add_option("--preview-dir", dir, "directory for the previews, DIR/step_NNNNNN.png (created if missing)")
      ->each([this](const std::string&) { dir_set = true; });
  auto extra = [this](const std::string&) { extra_set = true; };
  c->add_option("--preview-size", size, "preview image size WxH")->capture_default_str()->each(extra);
  c->add_option("--preview-mode", mode, "preview integrator: raymarch|shadow|pathtrace (1 sample per pixel)")
      ->capture_default_str()
      ->each(extra);
  c->add_option("--preview-tf", tf,
                "preview transfer function: a preset, JSON text or a JSON file (default: ramp, as vnr render)")
      ->each(extra);
}

std::optional<PreviewOptions> PreviewArgs::options() const {
  if (!enabled()) return std::nullopt;
  if (!every_set) fail("--preview-dir, --preview-size, --preview-mode and --preview-tf need --preview-every N");
  if (every <= 0) fail("--preview-every must be a positive number of steps, got {}", every);
  if (dir.empty()) fail("--preview-every needs --preview-dir DIR (where the previews are written)");
  // The picture as `vnr render` states it (the library's RenderSettings: its parsing and checks).
  RenderSettings r;
  parse_size(size, &r.width, &r.height, "--preview-size");
  r.mode = mode;
  r.tf = tf;
  try {
    r.validate([](const std::string& key) { return "--preview-" + key; });
  } catch (const Error& e) {
    fail("--preview-mode: {}", e.what());  // the only setting given here that validate checks
  }
  PreviewOptions o;
  o.every = every;
  o.dir = dir;
  o.width = r.width;
  o.height = r.height;
  o.mode = parse_render_mode(r.mode);
  try {
    o.tf = transfer_function_of(r.tf);
  } catch (const Error& e) {
    fail("--preview-tf: {}", e.what());
  }
  check_preview_options(o);  // creates and probes the directory
  return o;
}

}  // namespace vnr::cli
