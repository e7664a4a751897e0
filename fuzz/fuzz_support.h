#pragma once
// Shared by the libFuzzer targets: a private scratch folder for the APIs that take paths, and the rule
// that vnr::Error is the one acceptable failure (any other exception escapes and counts as a finding).
#include <unistd.h>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include "vnr/error.h"

namespace vnr::fuzz {

// One folder per fuzzing process (libFuzzer forks with -jobs), created on first use.
inline const std::string& scratch_dir() {
  static const std::string dir = [] {
    char templ[] = "/tmp/vnr_fuzz_XXXXXX";
    if (!mkdtemp(templ)) std::abort();
    return std::string(templ);
  }();
  return dir;
}

// Writes the input bytes to scratch_dir()/name and returns the full path.
inline std::string write_scratch(const std::string& name, const uint8_t* data, size_t size) {
  const std::string path = scratch_dir() + "/" + name;
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) std::abort();
  if (size && std::fwrite(data, 1, size, f) != size) std::abort();
  std::fclose(f);
  return path;
}

// Runs fn; a vnr::Error (bad input, clearly reported) is a pass.
template <typename Fn>
void expect_clean(Fn&& fn) {
  try {
    fn();
  } catch (const vnr::Error&) {
  }
}

}  // namespace vnr::fuzz
