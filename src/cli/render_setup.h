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

// Opens the input (with --volume as its ground truth), chooses the device (auto's fallback to the CPU
// is printed as a note) and applies every rendering option; the scene (--scene, else the input's)
// fills in what the options leave out.
// frames: how many will be accumulated (0 = unknown, e.g. --spp auto): --strategy auto takes the brick
// cache only where it pays (Renderer::choose_strategy).
CliRender open_cli_render(const std::string& input, const RenderArgs& a, const VolumeArgs& va, int frames = 0);

}  // namespace vnr::cli
