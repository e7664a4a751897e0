// Transfer functions from JSON: instantvnr's object (alphaArray base64 or list, colorControls,
// opacityControl, gaussianObjects), its standalone file and scene forms, and vnr's simple format.
#include <string>
#include "fuzz_support.h"
#include "vnr/json.h"
#include "vnr/render/transfer_function.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace vnr::fuzz;
  const std::string text(reinterpret_cast<const char*>(data), size);
  expect_clean([&] {
    const vnr::TransferFunction tf = vnr::tf_from_json(vnr::parse_json_text(text, "fuzz"), "fuzz");
    vnr::tf_from_json(vnr::tf_to_instantvnr_json(tf), "round trip");
  });
  return 0;
}
