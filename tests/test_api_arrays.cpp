// Arrays in memory as the Python module hands them to the library: samples of any dtype and byte
// order normalised like the raw loader, and a training session over a shared volume that trains the
// model `vnr train` trains from a file of the same values.
#include <gtest/gtest.h>
#include <cmath>
#include <cstring>
#include <fstream>
#include "test_support.h"
#include "vnr/error.h"
#include "vnr/vnr.h"
#include "vnr/train/session.h"

using namespace vnr;
using namespace vnr::test;

namespace {

const Int3 kDims{9, 7, 5};

// A raw file of `bytes` with its sidecar; returns the sidecar's path.
std::string write_raw(const TmpDir& dir, const std::vector<unsigned char>& bytes, const char* dtype, bool big) {
  std::ofstream(dir / "v.raw", std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
  const Json side = {{"file", "v.raw"}, {"dims", {kDims.x, kDims.y, kDims.z}}, {"dtype", dtype},
                     {"byte_order", big ? "big" : "little"}};
  std::ofstream(dir / "v.json") << side.dump();
  return dir / "v.json";
}

// Voxel values of type T with a non-trivial range, stored in the given byte order.
template <typename T>
std::vector<unsigned char> sample_bytes(bool big) {
  std::vector<unsigned char> out(kDims.count() * sizeof(T));
  for (uint64_t i = 0; i < kDims.count(); ++i) {
    const T v = T(40 + 30 * std::sin(0.3 * double(i)));
    unsigned char* p = out.data() + i * sizeof(T);
    std::memcpy(p, &v, sizeof(T));
    if (big) std::reverse(p, p + sizeof(T));
  }
  return out;
}

bool same_values(const Volume& a, const Volume& b) {
  return a.dims == b.dims && a.lo == b.lo && a.hi == b.hi && a.source_dtype == b.source_dtype &&
         std::memcmp(a.data.data(), b.data.data(), a.data.size() * sizeof(float)) == 0;
}

}  // namespace

TEST(ApiArrays, SamplesOfAnyDtypeAndByteOrderLoadLikeARawFile) {
  TmpDir dir;
  for (bool big : {false, true}) {
    auto u16 = sample_bytes<uint16_t>(big);
    EXPECT_TRUE(same_values(volume_from_samples(u16.data(), DType::UInt16, kDims, big),
                            open_volume(write_raw(dir, u16, "uint16", big))));
    auto i8 = sample_bytes<int8_t>(big);
    EXPECT_TRUE(same_values(volume_from_samples(i8.data(), DType::Int8, kDims, big), open_volume(write_raw(dir, i8, "int8", big))));
    auto f64 = sample_bytes<double>(big);
    Volume ranged = volume_from_samples(f64.data(), DType::Float64, kDims, big, 0.0, std::nullopt);
    VolumeOpenOptions o;
    o.raw.range_lo = 0.0;
    EXPECT_TRUE(same_values(ranged, open_volume(write_raw(dir, f64, "float64", big), o)));
  }
}

TEST(ApiArrays, ASharedVolumeTrainsTheModelOfItsFile) {
  TmpDir dir;
  auto bytes = sample_bytes<uint8_t>(false);
  TrainingSetup setup;
  setup.volume = write_raw(dir, bytes, "uint8", false);
  setup.config = "tiny";
  setup.batch = 1024;
  setup.seed = 5;
  setup.device = "cpu";
  auto from_file = open_training_session(setup);
  from_file->run(6);

  auto volume = std::make_shared<const Volume>(volume_from_samples(bytes.data(), DType::UInt8, kDims));
  TrainingSetup in_memory = setup;
  in_memory.volume = "array";
  in_memory.config_json = preset_config("tiny");  // the same config given as JSON
  auto shared = open_training_session(in_memory, volume);
  EXPECT_EQ(shared->data()->vol.get(), volume.get());  // shared, not copied
  shared->run(6);
  const Network& a = from_file->network();
  const Network& b = shared->network();
  ASSERT_EQ(a.params().size(), b.params().size());
  EXPECT_EQ(std::memcmp(a.params().data(), b.params().data(), a.params().size() * sizeof(float)), 0);
  EXPECT_EQ(shared->model().source_dtype, DType::UInt8);

  in_memory.data.sampler = "outofcore";
  EXPECT_THROW(open_training_session(in_memory, volume), Error);
}
