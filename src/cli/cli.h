#pragma once
#include <CLI/CLI.hpp>
#include <string>
#include "vnr/device.h"
#include "vnr/json.h"
#include "vnr/math.h"
#include "vnr/render_settings.h"
#include "vnr/units.h"
#include "vnr/volume.h"

namespace vnr {
struct Model;
}

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
  VolumeOpenOptions open() const { return VolumeOpenOptions{raw(), load()}; }
};

// --device auto|cpu|cuda on train, eval, decode and bench (auto: cuda when a device is visible).
void add_device_option(CLI::App* app, std::string& device);
// --precision auto|fp32|bf16 on eval, decode, render and bench infer|render (Network::set_inference_precision).
void add_precision_option(CLI::App* app, std::string& precision);
// --precision auto|fp32|bf16 on train and bench train (resolve_training_precision).
void add_training_precision_option(CLI::App* app, std::string& precision);
// A report's "precision": the CPU network's inference arithmetic, "fp32" or "bf16"; null on the GPU
// (its own fp16 MLP) or without a network (a grid).
Json precision_json(const Model* model, Device dev);

Int3 parse_dims(const std::string& s, const char* option = "--dims");  // X,Y,Z, positive
void write_report(const std::string& path, const Json& report);  // atomic; "" = no report
// Refuses to replace existing volume files (a decoded or generated volume must never silently
// overwrite someone's data) unless force is set.
void check_no_overwrite(const std::vector<std::string>& files, bool force);
// A compression ratio for people: two decimals, or two significant digits below 0.01 (a model larger
// than a tiny volume would otherwise read "0.00").
std::string format_ratio(double ratio);

// SIGINT/SIGTERM outside a graceful stop: one error line, the temporaries of unfinished saves removed,
// then the default action (so the exit status still says which signal). Installed by main();
// training guards hand signals back to it after their first one. SIGXFSZ is ignored (EFBIG errors).
extern "C" void exit_on_signal(int sig);
void install_exit_on_signal();
// SIGINT and SIGTERM both go to `handler`: every command treats the two alike (async-signal-safe).
void handle_stop_signals(void (*handler)(int));
// Routes SIGINT and SIGTERM to `handler` while it lives, then puts back what was there before.
class StopSignalScope {
public:
  explicit StopSignalScope(void (*handler)(int));
  ~StopSignalScope();
  StopSignalScope(const StopSignalScope&) = delete;
  StopSignalScope& operator=(const StopSignalScope&) = delete;

private:
  void (*previous_int_)(int);
  void (*previous_term_)(int);
};

void add_train(CLI::App& app);
void add_eval(CLI::App& app);
void add_decode(CLI::App& app);
void add_info(CLI::App& app);
void add_synth(CLI::App& app);
void add_convert(CLI::App& app);
void add_bench(CLI::App& app);
void add_render(CLI::App& app);
void add_view(CLI::App& app);  // only with VNR_VIEW (cmd_view.cpp)
void add_bench_render(CLI::App& bench);
void add_bench_rd(CLI::App& bench);  // cmd_bench_rd.cpp

// Rendering options shared by `vnr render`, `vnr bench render` and `vnr mpi render`: CLI11 writes the
// library's RenderSettings (vnr/render_settings.h) directly, text forms such as WxH parsed on the way.
struct RenderArgs {
  RenderSettings s;    // defaults: RenderSettings's (a command may change them before add)
  std::string volume;  // a model's ground-truth volume
  int threads = 0;
  void add(CLI::App* app);
};
void parse_size(const std::string& s, int* w, int* h, const char* option = "--size");

}  // namespace vnr::cli
