// The viewer's WebSocket messages: the parsing half (parse_client_message, which checks every field
// before any engine call) and the binary frame splitter.
#include <string_view>
#include "fuzz_support.h"
#include "view/protocol.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace vnr::fuzz;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  expect_clean([&] { vnr::view::parse_client_message(text); });
  expect_clean([&] { vnr::view::split_frame_message(text); });
  return 0;
}
