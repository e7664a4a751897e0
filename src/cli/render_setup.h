#pragma once
// What `vnr render` and `vnr bench render` share: the command line's rendering options applied to a
// vnr::Renderer over the opened input.
#include <memory>
#include <string>
#include "cli.h"
#include "vnr/renderer.h"

namespace vnr::cli {

struct CliRender {
  std::unique_ptr<RenderInput> input;  // on the heap: the renderer points into it
  std::unique_ptr<Renderer> renderer;
  float orbit_elevation = 0;  // degrees, from --orbit
};

// Opens the input (with --volume as its ground truth) and sets up its renderer with the settings
// (vnr::setup_renderer); the library's notes (e.g. auto's fallback to the CPU) are printed.
CliRender open_cli_render(const std::string& input, const RenderArgs& a, const VolumeArgs& va);

}  // namespace vnr::cli
