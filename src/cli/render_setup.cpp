#include "render_setup.h"
#include <algorithm>
#include <cstdio>

namespace vnr::cli {

CliRender open_cli_render(const std::string& input, const RenderArgs& a, const VolumeArgs& va) {
  // Before a large input is read, naming the settings as the options that set them (max_spp: --max-spp).
  a.s.validate([](const std::string& key) {
    std::string option = "--" + key;
    std::replace(option.begin(), option.end(), '_', '-');
    return option;
  });
  CliRender c;
  c.input = std::make_unique<RenderInput>(open_render_input(input, a.volume, va.open(), parse_precision(a.s.precision)));
  RenderSetup setup = setup_renderer(c.input->model ? &*c.input->model : nullptr,
                                     c.input->volume ? &*c.input->volume : nullptr, c.input->scene, a.s);
  for (const std::string& note : setup.notes) std::fprintf(stderr, "note: %s\n", note.c_str());
  c.renderer = std::move(setup.renderer);
  c.orbit_elevation = setup.orbit_elevation;
  return c;
}

}  // namespace vnr::cli
