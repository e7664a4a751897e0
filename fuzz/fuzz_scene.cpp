// instantvnr scene JSON: as a render scene (load_scene: camera, TF, light) and as a volume descriptor
// (describe_volume: dataSource), with a 4 KiB data file beside it.
#include <vector>
#include "fuzz_support.h"
#include "vnr/scene.h"
#include "vnr/volume/volume.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace vnr::fuzz;
  static const bool ready = [] {
    std::vector<uint8_t> bytes(4096);
    for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = uint8_t(i * 5);
    write_scratch("data.raw", bytes.data(), bytes.size());
    return true;
  }();
  (void)ready;
  const std::string path = write_scratch("scene.json", data, size);
  expect_clean([&] { vnr::load_scene(path); });
  expect_clean([&] {
    const vnr::VolumeDesc d = vnr::describe_volume(path);
    if (d.dims.count() <= 4096) vnr::load_volume(d);
  });
  return 0;
}
