#include "preview.h"
#include <cstdio>
#include "vnr/error.h"
#include "vnr/render/renderer.h"
#include "vnr/render/transfer_function.h"

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
  c->add_option("--preview-tf", tf, "preview transfer function: a preset or a JSON file (default: ramp, as vnr render)")
      ->each(extra);
}

std::optional<PreviewOptions> PreviewArgs::options() const {
  if (!enabled()) return std::nullopt;
  if (!every_set) fail("--preview-dir, --preview-size, --preview-mode and --preview-tf need --preview-every N");
  if (every <= 0) fail("--preview-every must be a positive number of steps, got {}", every);
  if (dir.empty()) fail("--preview-every needs --preview-dir DIR (where the previews are written)");
  PreviewOptions o;
  o.every = every;
  o.dir = dir;
  char tail;
  if (std::sscanf(size.c_str(), "%dx%d%c", &o.width, &o.height, &tail) != 2 || o.width < 1 || o.height < 1 ||
      o.width > 32768 || o.height > 32768)
    fail("--preview-size expects WxH (positive, at most 32768), got '{}'", size);
  try {
    o.mode = parse_render_mode(mode);
  } catch (const Error& e) {
    fail("--preview-mode: {}", e.what());
  }
  try {
    o.tf = tf.empty() ? tf_preset("ramp") : load_transfer_function(tf);
  } catch (const Error& e) {
    fail("--preview-tf: {}", e.what());
  }
  check_preview_options(o);  // creates and probes the directory
  return o;
}

}  // namespace vnr::cli
