// Sidecar JSON ({"file", "dims", "dtype", "byte_order", ...}) through describe_volume, and the load of
// what it describes when that is small (a 4 KiB data file sits beside it under two names).
#include <vector>
#include "fuzz_support.h"
#include "vnr/volume/volume.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace vnr::fuzz;
  static const bool ready = [] {
    std::vector<uint8_t> bytes(4096);
    for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = uint8_t(i * 7);
    write_scratch("data.raw", bytes.data(), bytes.size());
    write_scratch("t1.raw", bytes.data(), bytes.size());
    return true;
  }();
  (void)ready;
  const std::string path = write_scratch("volume.json", data, size);
  expect_clean([&] {
    const vnr::VolumeDesc d = vnr::describe_volume(path);
    if (d.dims.count() <= 4096) vnr::load_volume(d);
  });
  return 0;
}
