#pragma once
#include <CLI/CLI.hpp>
#include <string>
#include "vnr/core/json.h"
#include "vnr/core/math.h"
#include "vnr/volume/volume.h"

namespace vnr::cli {

// Options every command that reads a volume accepts (see `vnr train --help`).
struct VolumeArgs {
  std::string dims, dtype, endian, range, nan_policy = "error";
  uint64_t offset = 0;
  bool offset_set = false;
  int timestep = -1;
  void add(CLI::App* app);
  RawOptions raw() const;
  LoadOptions load() const;
};

Int3 parse_dims(const std::string& s);
void write_report(const std::string& path, const Json& report);  // atomic; "" = no report
// Refuses to replace existing volume files (a decoded or generated volume must never silently
// overwrite someone's data) unless force is set.
void check_no_overwrite(const std::vector<std::string>& files, bool force);
std::string human_bytes(double bytes);

void add_train(CLI::App& app);
void add_eval(CLI::App& app);
void add_decode(CLI::App& app);
void add_info(CLI::App& app);
void add_synth(CLI::App& app);
void add_convert(CLI::App& app);
void add_bench(CLI::App& app);

}  // namespace vnr::cli
