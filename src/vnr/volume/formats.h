#pragma once
// Internal to the volume layer: the per-format descriptor readers behind describe_volume().
#include <string>
#include <vector>
#include "vnr/json.h"
#include "vnr/volume/volume.h"

namespace vnr::detail {

// What a descriptor says before command-line overrides and timestep selection are applied.
struct Source {
  VolumeDesc desc;                 // offset = the first timestep's offset; n_timesteps filled in
  std::vector<std::string> files;  // one data file per timestep (scene/DIVA lists); empty = all in desc.path
  bool data_at_end = false;        // NRRD "byte skip: -1": offset = file size - data size
  std::string origin;              // the descriptor named in messages ("" for a plain raw file)
};

// "file" is one data file (with an optional 4th dim: timesteps stored one after another in it) or an
// array of files, one per timestep (a file list; same size each, checked here).
Source describe_sidecar(const std::string& json_path, const Json& j);
Source describe_scene(const std::string& json_path, const Json& j);  // instantvnr VIDI3D or DIVA
Source describe_nrrd(const std::string& path);

// "little"/"big" (also "le"/"be", "little_endian"/"big_endian", any case) -> big endian?
// Errors read "<prefix>unknown <name> '<word>' (allowed: little, big)".
bool parse_byte_order(const std::string& word, const std::string& prefix, const std::string& name);

// "16x8x8" / "16x8x8x3"
std::string dims_string(const Int3& d, int n_timesteps = 1);

}  // namespace vnr::detail
