#pragma once
// `vnr train --preview-every N --preview-dir DIR [--preview-size WxH] [--preview-mode M] [--preview-tf TF]`:
// renders the model as it trains into DIR/step_NNNNNN.png (vnr/online.h: the online
// training-and-rendering loop without a window).
#include <CLI/CLI.hpp>
#include <cstdint>
#include <optional>
#include <string>
#include "vnr/online.h"

namespace vnr::cli {

struct PreviewArgs {
  int64_t every = 0;  // 0: no previews
  std::string dir, size = "256x256", mode = "raymarch", tf;  // tf "": `vnr render`'s default ("ramp")
  bool every_set = false, dir_set = false, extra_set = false;  // which flags were given (set by add()'s options)
  void add(CLI::App* app);
  bool enabled() const { return every_set || dir_set || extra_set; }
  // Validates the flags and prepares the directory (created if missing, probed for writing); nullopt
  // when no preview flag was given. Call before loading the volume: mistakes give one clear error line
  // before any training.
  std::optional<PreviewOptions> options() const;
};

}  // namespace vnr::cli
