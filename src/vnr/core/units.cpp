#include "vnr/units.h"
#include <unistd.h>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include "vnr/error.h"

namespace vnr {

uint64_t parse_byte_size(const std::string& text) {
  const char* s = text.c_str();
  char* end = nullptr;
  double v = std::strtod(s, &end);
  if (end == s || !std::isfinite(v) || v < 0)
    fail("invalid size '{}' (examples: 4096, 512KiB, 16MiB, 2GiB)", text);
  std::string unit;
  for (const char* p = end; *p; ++p)
    if (!std::isspace(static_cast<unsigned char>(*p))) unit += char(std::tolower(static_cast<unsigned char>(*p)));
  if (!unit.empty() && unit.back() == 'b') unit.pop_back();
  if (!unit.empty() && unit.back() == 'i') unit.pop_back();
  double mult;
  if (unit.empty()) mult = 1;
  else if (unit == "k") mult = 1024.0;
  else if (unit == "m") mult = 1024.0 * 1024;
  else if (unit == "g") mult = 1024.0 * 1024 * 1024;
  else if (unit == "t") mult = 1024.0 * 1024 * 1024 * 1024;
  else fail("invalid size '{}': unknown unit (allowed: B, KiB, MiB, GiB, TiB)", text);
  double bytes = v * mult;
  if (bytes >= 1.8e19) fail("invalid size '{}': too large", text);
  return uint64_t(std::llround(bytes));
}

uint64_t physical_memory_bytes() {
  long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGESIZE);
  return pages > 0 && page > 0 ? uint64_t(pages) * uint64_t(page) : (uint64_t(8) << 30);
}

namespace {
// VNR_MEMORY_LIMIT caps what the memory checks allow (a shared node, a test, a fuzzer's small budget).
uint64_t memory_limit_from_env() {
  const char* text = std::getenv("VNR_MEMORY_LIMIT");
  if (!text || !*text) return UINT64_MAX;
  try {
    return parse_byte_size(text);
  } catch (const Error& e) {
    fail("VNR_MEMORY_LIMIT: {}", e.what());
  }
}

uint64_t meminfo_available_bytes() {
  if (std::FILE* f = std::fopen("/proc/meminfo", "r")) {
    char line[256];
    unsigned long long kb = 0;
    bool found = false;
    while (std::fgets(line, sizeof line, f))
      if (std::sscanf(line, "MemAvailable: %llu kB", &kb) == 1) {
        found = true;
        break;
      }
    std::fclose(f);
    if (found) return uint64_t(kb) * 1024;
  }
  return physical_memory_bytes();
}
}  // namespace

uint64_t available_memory_bytes() { return std::min(meminfo_available_bytes(), memory_limit_from_env()); }

std::string human_bytes(double b) {
  const char* u[] = {"B", "KiB", "MiB", "GiB", "TiB"};
  int i = 0;
  while (b >= 1024 && i < 4) b /= 1024, ++i;
  return fmt::format("{:.2f} {}", b, u[i]);
}

}  // namespace vnr
