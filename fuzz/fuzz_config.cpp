// Model configs (the four-object tcnn JSON or {"params": {...}}) through ModelConfig::from_json, as
// load_config reads a config file.
#include <string>
#include "fuzz_support.h"
#include "vnr/json.h"
#include "vnr/model_config.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace vnr::fuzz;
  const std::string text(reinterpret_cast<const char*>(data), size);
  expect_clean([&] { vnr::ModelConfig::from_json(vnr::parse_json_text(text, "fuzz")); });
  return 0;
}
