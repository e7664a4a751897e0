// Model files through load_model: vnr's .vnr, or (built with VNR_FUZZ_BSON) instantvnr's BSON params.
#include "fuzz_support.h"
#include "vnr/train/model.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace vnr::fuzz;
#ifdef VNR_FUZZ_BSON
  const std::string path = write_scratch("params.bson", data, size);
#else
  const std::string path = write_scratch("model.vnr", data, size);
#endif
  expect_clean([&] { vnr::load_model(path); });
  return 0;
}
