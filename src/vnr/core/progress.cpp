#include "vnr/progress.h"
#include <unistd.h>
#include <algorithm>
#include <cstdio>
#include <fmt/format.h>

namespace vnr {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

double upper_median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

std::string eta_text(double frac, double elapsed) {
  // Before 1 % of the work or half a second, the rate is mostly start-up (CUDA context, first-touch
  // allocations, warm-up) and the extrapolation can be off by orders of magnitude.
  if (frac >= 1) return "ETA 0s";
  if (frac < 0.01 || elapsed < 0.5) return "ETA ?";
  return fmt::format("ETA {:.0f}s", elapsed * (1 - frac) / frac);
}

Progress::Progress(std::string label, double total, bool quiet)
    : label_(std::move(label)), total_(total > 0 ? total : 1), quiet_(quiet), tty_(::isatty(2)) {
  start_ = last_draw_ = std::chrono::steady_clock::now();
}

void Progress::update(double done, const std::string& extra) {
  if (quiet_) return;
  double frac = done / total_;
  if (frac > 1) frac = 1;
  double el = seconds_since(start_);
  const std::string eta = eta_text(frac, el);
  if (tty_) {
    if (seconds_since(last_draw_) < 0.1 && frac < 1) return;
    last_draw_ = std::chrono::steady_clock::now();
    int w = 24, fill = int(frac * w);
    std::fprintf(stderr, "\r%s [%s%s] %3d%% %s %s   ", label_.c_str(), std::string(fill, '#').c_str(),
                 std::string(w - fill, '.').c_str(), int(frac * 100), extra.c_str(), eta.c_str());
  } else {
    int dec = int(frac * 10);
    if (dec == last_decile_) return;
    last_decile_ = dec;
    std::fprintf(stderr, "%s %3d%% %s %s\n", label_.c_str(), dec * 10, extra.c_str(), eta.c_str());
  }
  std::fflush(stderr);
}

void Progress::finish(const std::string& extra) {
  if (quiet_) return;
  if (tty_) std::fprintf(stderr, "\r%s done in %.1fs %s\033[K\n", label_.c_str(), seconds_since(start_), extra.c_str());
  else std::fprintf(stderr, "%s done in %.1fs %s\n", label_.c_str(), seconds_since(start_), extra.c_str());
}

}  // namespace vnr
