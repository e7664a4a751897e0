// NRRD headers through describe_volume and load_volume: attached (.nrrd, data after the header, raw or
// gzip) or, built with VNR_FUZZ_DETACHED, a detached .nhdr naming data.raw beside it.
#include <vector>
#include "fuzz_support.h"
#include "vnr/volume/volume.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace vnr::fuzz;
#ifdef VNR_FUZZ_DETACHED
  static const bool ready = [] {
    std::vector<uint8_t> bytes(4096);
    for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = uint8_t(i * 13);
    write_scratch("data.raw", bytes.data(), bytes.size());
    return true;
  }();
  (void)ready;
  const std::string path = write_scratch("volume.nhdr", data, size);
#else
  const std::string path = write_scratch("volume.nrrd", data, size);
#endif
  expect_clean([&] {
    const vnr::VolumeDesc d = vnr::describe_volume(path);
    if (d.dims.count() <= (1 << 16)) vnr::load_volume(d);
  });
  return 0;
}
