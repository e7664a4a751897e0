// vnr: command-line front end of libvnr. Each subcommand lives in its own file; errors from the
// library arrive as vnr::Error and are printed as one line with a non-zero exit status.
#include <unistd.h>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include "cli.h"
#include "mpi_cli.h"
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/threads.h"
#include "vnr/device.h"
#include "vnr/model.h"
#include "vnr/version.h"

namespace vnr::cli {

void VolumeArgs::add(CLI::App* app) {
  app->add_option("--dims", dims, "voxels per axis X,Y,Z (raw files)");
  app->add_option("--dtype", dtype, "int8|uint8|int16|uint16|int32|uint32|float32|float64 (raw files)");
  app->add_option("--endian", endian, "little|big (raw files; default little)")->check(CLI::IsMember({"little", "big"}));
  app->add_option("--offset", offset, "header bytes to skip (raw files)")->each([this](const std::string&) { offset_set = true; });
  app->add_option("--timestep", timestep, "which timestep of a 4-D volume");
  app->add_option("--range", range, "value range LO,HI in original units (default: sidecar, else data min/max)");
  app->add_option("--nan", nan_policy, "how to treat NaN/Inf: error|zero|clamp")->check(CLI::IsMember({"error", "zero", "clamp"}));
}

RawOptions VolumeArgs::raw() const {
  RawOptions o;
  if (!dims.empty()) o.dims = parse_dims(dims);
  if (!dtype.empty()) o.dtype = dtype;
  if (!endian.empty()) o.endian = endian;
  if (offset_set) o.offset = offset;
  if (timestep >= 0) o.timestep = timestep;
  if (!range.empty()) {
    double lo, hi;
    char c;
    if (std::sscanf(range.c_str(), "%lf%c%lf", &lo, &c, &hi) != 3 || c != ',' || !(hi >= lo))
      fail("--range expects LO,HI with LO <= HI, got '{}'", range);
    o.range_lo = lo;
    o.range_hi = hi;
  }
  return o;
}

LoadOptions VolumeArgs::load() const {
  LoadOptions o;
  o.non_finite = parse_non_finite_policy(nan_policy);
  return o;
}

void add_precision_option(CLI::App* app, std::string& precision) {
  app->add_option("--precision", precision,
                   "CPU network inference arithmetic: bf16 (weights and activations rounded to bf16, sums in fp32; "
                   "needs AVX512-BF16; faster on AMD CPUs), fp32, or auto = bf16 on AMD CPUs with AVX512-BF16, where "
                   "it pays (on Intel ones it does not), else fp32")
      ->check(CLI::IsMember({"auto", "fp32", "bf16"}))
      ->capture_default_str();
}

void add_training_precision_option(CLI::App* app, std::string& precision) {
  app->add_option("--precision", precision,
                   "CPU training arithmetic of the MLP: bf16 (weights, activations and gradients rounded to bf16, sums "
                   "and Adam in fp32; needs AVX512-BF16; faster steps for wide MLPs on AMD CPUs), fp32, or auto = "
                   "bf16 on AMD CPUs with AVX512-BF16 when the MLP is at least 32 wide (16-wide ones train faster in "
                   "fp32; on Intel CPUs bf16 is no faster), else fp32")
      ->check(CLI::IsMember({"auto", "fp32", "bf16"}))
      ->capture_default_str();
}

Json precision_json(const Model* model, Device dev) {
  return model && dev == Device::Cpu ? Json(precision_name(inference_precision(*model))) : Json(nullptr);
}

void add_device_option(CLI::App* app, std::string& device) {
  app->add_option("--device", device, "auto (cuda when a CUDA device is visible, else cpu), cpu or cuda")
      ->check(CLI::IsMember({"auto", "cpu", "cuda"}))
      ->capture_default_str();
}

Int3 parse_dims(const std::string& s, const char* option) {
  long long v[3];
  char tail;
  if (std::sscanf(s.c_str(), "%lld,%lld,%lld%c", &v[0], &v[1], &v[2], &tail) != 3)
    fail("{} expects X,Y,Z (three positive integers), got '{}'", option, s);
  for (long long d : v)
    if (d <= 0) fail("{} must be positive, got '{}'", option, s);
  return Int3{v[0], v[1], v[2]};
}

void write_report(const std::string& path, const Json& report) {
  if (path.empty()) return;
  write_file_atomic(path, report.dump(2) + "\n");
}

void check_no_overwrite(const std::vector<std::string>& files, bool force) {
  if (force) return;
  for (const std::string& f : files)
    if (file_exists(f)) fail("'{}' already exists; choose another output or pass --force to replace it", f);
}

extern "C" void exit_on_signal(int sig) {
  static const char kTerm[] = "vnr: error: terminated (SIGTERM); unfinished output discarded\n";
  static const char kInt[] = "vnr: error: interrupted (SIGINT); unfinished output discarded\n";
  vnr::remove_pending_temporaries();
  if (sig == SIGTERM) (void)!::write(2, kTerm, sizeof kTerm - 1);
  else (void)!::write(2, kInt, sizeof kInt - 1);
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}

void install_exit_on_signal() {
  for (int sig : {SIGINT, SIGTERM})
    if (std::signal(sig, exit_on_signal) == SIG_IGN) std::signal(sig, SIG_IGN);  // keep nohup's choice
  // Past a file-size limit (ulimit -f) a write then fails with EFBIG and is reported like a full disk,
  // instead of the process dying mid-write with its temporaries left behind.
  std::signal(SIGXFSZ, SIG_IGN);
}

void handle_stop_signals(void (*handler)(int)) {
  std::signal(SIGINT, handler);
  std::signal(SIGTERM, handler);
}

StopSignalScope::StopSignalScope(void (*handler)(int))
    : previous_int_(std::signal(SIGINT, handler)), previous_term_(std::signal(SIGTERM, handler)) {}

StopSignalScope::~StopSignalScope() {
  std::signal(SIGINT, previous_int_ == SIG_ERR ? exit_on_signal : previous_int_);
  std::signal(SIGTERM, previous_term_ == SIG_ERR ? exit_on_signal : previous_term_);
}

std::string format_ratio(double r) { return r >= 0.01 || r == 0 ? fmt::format("{:.2f}", r) : fmt::format("{:.2g}", r); }

}  // namespace vnr::cli

int main(int argc, char** argv) {
  using namespace vnr::cli;
  CLI::App app{"vnr: volumetric neural representations - compress volumes into neural networks and evaluate them"};
  app.require_subcommand(1);
  app.set_version_flag("--version", []() {  // lazily: querying CUDA devices takes a moment
    return std::string("vnr ") + vnr::version() + " (backends: cpu [" + vnr::kernels::simd_target_name() + "]; " +
           vnr::cuda::backend_summary() + ")";
  });
  install_exit_on_signal();
  add_train(app);
  add_eval(app);
  add_decode(app);
  add_info(app);
  add_synth(app);
  add_convert(app);
  add_bench(app);
  add_render(app);
#ifdef VNR_HAVE_VIEW
  add_view(app);
#endif
  MpiCli mpi(&argc, &argv, app);  // a no-op unless built with MPI and started by mpirun/srun
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    // One line, like every other error; --help has the details.
    return mpi.print_error(fmt::format("{} (see 'vnr --help' or 'vnr COMMAND --help')", e.what()), true,
                           e.get_exit_code() != 0 ? e.get_exit_code() : 2);
  } catch (const vnr::Error& e) {
    return mpi.print_error(e.what(), mpi.agreed(e), 1);
  } catch (const std::bad_alloc&) {
    return mpi.print_error("out of memory", false, 1);
  } catch (const std::exception& e) {
    return mpi.print_error(e.what(), false, 1);
  }
  return 0;
}
