#pragma once
#include <chrono>
#include <string>
#include <vector>

namespace vnr {

// A one-line progress bar on stderr ("[#####.....] 42% ... ETA 12s"). On a terminal it redraws
// in place; otherwise it prints a line every 10%. Quiet mode prints nothing.
class Progress {
public:
  Progress(std::string label, double total, bool quiet = false);
  void update(double done, const std::string& extra = "");
  void finish(const std::string& extra = "");

private:
  std::string label_;
  double total_;
  bool quiet_, tty_;
  int last_decile_ = -1;
  std::chrono::steady_clock::time_point start_, last_draw_;
};

double seconds_since(std::chrono::steady_clock::time_point t0);
// The upper median of timings (v[n / 2] sorted), 0 for none: what every timing report takes.
double upper_median(std::vector<double> v);

// "ETA 12s" from the fraction done and the seconds elapsed; "ETA ?" while too little is done to say.
std::string eta_text(double frac, double elapsed);

}  // namespace vnr
