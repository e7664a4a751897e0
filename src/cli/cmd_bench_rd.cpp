// `vnr bench rd VOLUME`: runs the rate-distortion benchmark of include/vnr/rate_distortion.h, prints a
// line per point, writes the JSON report and, with --plot, the PSNR-ratio plot (bench/plot_rd.py).
#include <spawn.h>
#include <sys/wait.h>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fmt/format.h>
#include "cli.h"
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/threads.h"
#include "vnr/rate_distortion.h"

extern char** environ;

namespace vnr::cli {
namespace {

struct RdArgs {
  std::string volume, report, plot, peers, ratios, bounds, zfp_rates, times, config = "auto", device = "auto",
              residuals = "auto";
  double seconds = 60, time_ratio = 64;
  int64_t steps = -1;
  int threads = 0;
  VolumeArgs vol;
};

std::vector<double> parse_list(const std::string& text, const char* flag) {
  std::vector<double> out;
  size_t start = 0;
  while (start <= text.size()) {
    const size_t comma = std::min(text.find(',', start), text.size());
    const std::string item = text.substr(start, comma - start);
    char* end = nullptr;
    const double v = std::strtod(item.c_str(), &end);
    if (item.empty() || *end != '\0' || !(v > 0)) fail("{}: expected positive numbers separated by commas, got '{}'", flag, text);
    out.push_back(v);
    start = comma + 1;
  }
  return out;
}

// plot_rd.py installed beside the executable (<prefix>/share/vnr/, from bench/), else the source tree's.
std::string plot_script() {
  std::error_code ec;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    const std::filesystem::path installed = exe.parent_path().parent_path() / "share" / "vnr" / "plot_rd.py";
    if (std::filesystem::exists(installed)) return installed.string();
  }
  if (std::filesystem::exists(VNR_PLOT_RD_SCRIPT)) return VNR_PLOT_RD_SCRIPT;
  fail("--plot: cannot find plot_rd.py (looked in {}/../share/vnr and {})", exe.parent_path().string(),
       VNR_PLOT_RD_SCRIPT);
}

// Runs Debian's python3 on the script with the paths as arguments (no shell: any file name is safe).
void plot(const std::string& report, const RdArgs& a) {
  std::vector<std::string> args = {"/usr/bin/python3", plot_script(), report, "-o", a.plot};
  if (!a.peers.empty()) args.insert(args.end(), {"--peers", a.peers});
  std::vector<char*> argv;
  for (std::string& s : args) argv.push_back(s.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  if (posix_spawn(&pid, argv[0], nullptr, nullptr, argv.data(), environ) != 0)
    fail("--plot: cannot run /usr/bin/python3 (Debian's python3 and python3-matplotlib draw the plot)");
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
    fail("--plot: {} {} failed (it needs python3-matplotlib)", args[0], args[1]);
  std::printf("plot: %s\n", a.plot.c_str());
}

void run_rd(const RdArgs& a) {
  set_num_threads(a.threads);
  RdOptions o;
  if (!a.ratios.empty()) o.ratios = parse_list(a.ratios, "--ratios");
  if (a.bounds == "none") o.rel_bounds.clear();
  else if (!a.bounds.empty()) o.rel_bounds = parse_list(a.bounds, "--bounds");
  if (a.zfp_rates == "none") o.zfp_rates.clear();
  else if (!a.zfp_rates.empty()) o.zfp_rates = parse_list(a.zfp_rates, "--zfp-rates");
  if (!a.times.empty()) o.times = parse_list(a.times, "--times");
  if (!(a.time_ratio > 0)) fail("--time-ratio must be positive, got {}", a.time_ratio);
  o.time_ratio = a.time_ratio;
  for (double b : o.rel_bounds)
    if (b >= 1) fail("--bounds are fractions of the value range (below 1), got {}", b);
  if (!(a.seconds > 0) && a.steps <= 0) fail("--seconds must be positive");
  if (!a.plot.empty() && a.report.empty()) fail("--plot needs --report (the plot is drawn from it)");
  if (!a.peers.empty() && !std::filesystem::exists(a.peers)) fail("--peers: no such file '{}'", a.peers);
  o.seconds = a.seconds;
  o.steps = a.steps;
  o.config = a.config;
  o.residuals = a.residuals;
  o.device = a.device;
  o.message = [](const std::string& line) {
    std::printf("%s\n", line.c_str());
    std::fflush(stdout);
  };
  const Volume vol = open_volume(a.volume, a.vol.open());
  std::printf("rate-distortion of %s (%lldx%lldx%lld %s): ZFP, then vnr at %zu ratios, %s each\n", a.volume.c_str(),
              (long long)vol.dims.x, (long long)vol.dims.y, (long long)vol.dims.z, dtype_name(vol.source_dtype),
              o.ratios.size(), a.steps > 0 ? fmt::format("{} steps", a.steps).c_str() : fmt::format("{:g}s", a.seconds).c_str());
  const RdReport rep = run_rate_distortion(a.volume, vol, o);
  if (!a.report.empty()) write_report(a.report, rep.to_json());
  if (!a.plot.empty()) plot(a.report, a);
}

}  // namespace

void add_bench_rd(CLI::App& bench) {
  auto a = std::make_shared<RdArgs>();
  CLI::App* c = bench.add_subcommand("rd", "rate-distortion: vnr at target ratios and error bounds beside ZFP");
  c->add_option("volume", a->volume, "volume")->required();
  c->add_option("--seconds", a->seconds, "training time per vnr model")->capture_default_str();
  c->add_option("--steps", a->steps, "training steps per vnr model (instead of --seconds)");
  c->add_option("--times", a->times,
                "PSNR against training time: models at --time-ratio trained for each of these budgets in seconds "
                "(e.g. 20,60,120)");
  c->add_option("--time-ratio", a->time_ratio, "target ratio of the --times models")->capture_default_str();
  c->add_option("--ratios", a->ratios, "vnr target ratios (default 8,16,32,64,128,256,512)");
  c->add_option("--bounds", a->bounds, "error bounds as fractions of the range (default 1e-2,1e-3; none: no bounded points)");
  c->add_option("--zfp-rates", a->zfp_rates, "ZFP fixed rates in bits per value (default 0.5,1,2,4,8; none: no ZFP points)");
  c->add_option("--config", a->config, "vnr preset or config file (auto: as vnr train's default)")->capture_default_str();
  c->add_option("--residuals", a->residuals, "the ratio points' --residuals (auto, off)")
      ->capture_default_str()
      ->check(CLI::IsMember({"auto", "off"}));
  c->add_option("--threads", a->threads, "CPU threads (default: all cores)");
  c->add_option("--report", a->report, "write the points as JSON");
  c->add_option("--plot", a->plot, "draw PSNR against ratio into a PNG (needs --report and python3-matplotlib)");
  c->add_option("--peers", a->peers, "other codecs' figures to draw beside (JSON, e.g. bench/peers_rd.json)");
  add_device_option(c, a->device);
  a->vol.add(c);
  c->callback([a]() { run_rd(*a); });
}

}  // namespace vnr::cli
