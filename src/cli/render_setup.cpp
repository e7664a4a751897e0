#include "render_setup.h"
#include <cstdio>

namespace vnr::cli {

CliRender open_cli_render(const std::string& input, const RenderArgs& a, const VolumeArgs& va) {
  a.s.validate(option_name_of);  // before a large input is read, naming the options (max_spp: --max-spp)
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
