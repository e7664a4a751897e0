// Hostile headers: a volume that claims 10^12 voxels, a config with a 2^40-entry table, a model whose
// parameter bytes disagree with its file size. Each is refused before any large allocation, with the
// sizes in the message.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#include <zlib.h>
#include <filesystem>
#include <fstream>
#include "test_support.h"
#include "vnr/error.h"
#include "vnr/units.h"
#include "vnr/model.h"
#include "vnr/model_config.h"
#include "vnr/nn/network.h"
#include "vnr/train/model.h"
#include "vnr/volume/volume.h"

namespace vnr::test {
namespace {

void write_text(const std::string& path, const std::string& text) { std::ofstream(path, std::ios::binary) << text; }

// A detached NRRD header over a tiny gzip stream: the header's dims cannot be checked against the file
// size, so only the in-core limit stands between it and a 4 TB allocation.
std::string tera_voxel_gzip_nrrd(const std::string& dir) {
  gzFile gz = gzopen((dir + "/tiny.gz").c_str(), "wb");
  gzwrite(gz, "abcd", 4);
  gzclose(gz);
  write_text(dir + "/tera.nhdr",
             "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 10000 10000 10000\nencoding: gzip\ndata file: tiny.gz\n");
  return dir + "/tera.nhdr";
}

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(Limits, InCoreLoadOfTeraVoxelsIsRefusedWithTheSizes) {
  const std::string path = tera_voxel_gzip_nrrd(temp_dir("vnr_limits"));
  const VolumeDesc d = describe_volume(path);
  const std::string msg = error_of([&] { load_volume(d); });
  EXPECT_NE(msg.find("dims 10000x10000x10000 = 1e+12 voxels x 4 bytes = 3.64 TiB exceeds the memory available"),
            std::string::npos)
      << msg;
  EXPECT_NE(msg.find("out-of-core"), std::string::npos) << msg;
}

// The same load in a child whose address space is capped at 1 GiB: had it tried the allocation, the
// message would be the allocator's failure, not the limit's.
TEST(Limits, TeraVoxelRefusalAllocatesNothingLarge) {
#ifdef VNR_SANITIZE_BUILD
  GTEST_SKIP() << "a sanitizer's shadow memory already exceeds any address-space cap (RLIMIT_AS)";
#endif
  const std::string path = tera_voxel_gzip_nrrd(temp_dir("vnr_limits"));
  const pid_t pid = ::fork();
  if (pid == 0) {
    rlimit r{rlim_t(1) << 30, rlim_t(1) << 30};
    ::setrlimit(RLIMIT_AS, &r);
    try {
      load_volume(describe_volume(path));
    } catch (const Error& e) {
      ::_exit(std::string(e.what()).find("exceeds the memory available") != std::string::npos ? 0 : 2);
    } catch (...) {
      ::_exit(3);
    }
    ::_exit(4);
  }
  int st = 0;
  ::waitpid(pid, &st, 0);
  ASSERT_TRUE(WIFEXITED(st));
  EXPECT_EQ(WEXITSTATUS(st), 0);
}

// An uncompressed header claiming 10^12 voxels is refused by the data file's size, naming both.
TEST(Limits, RawHeaderClaimingTeraVoxelsIsRefusedByTheFileSize) {
  const std::string dir = temp_dir("vnr_limits");
  write_text(dir + "/small.raw", std::string(64, '\0'));
  write_text(dir + "/tera_raw.nhdr",
             "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 10000 10000 10000\nencoding: raw\ndata file: small.raw\n");
  const std::string msg = error_of([&] { describe_volume(dir + "/tera_raw.nhdr"); });
  EXPECT_NE(msg.find("has 64 bytes, expected 1000000000000"), std::string::npos) << msg;
}

TEST(Limits, ConfigWithA2To40EntryTableIsRefused) {
  Json j = preset_config("small");
  j["encoding"]["log2_hashmap_size"] = 40;
  const std::string msg = error_of([&] { ModelConfig::from_json(j); });
  EXPECT_NE(msg.find("a table of 2^40 entries per level exceeds the limit of 2^30"), std::string::npos) << msg;
}

// A dense grid of 2^31 entries x 8 features (17e9 parameters, 96 GiB) is refused before the parameter
// vectors are allocated, naming the count.
TEST(Limits, AbsurdParameterCountIsRefusedBeforeAllocating) {
  Json j = preset_config("small");
  j["encoding"] = {{"otype", "DenseGrid"}, {"n_levels", 1}, {"n_features_per_level", 8}, {"base_resolution", 1300}};
  const ModelConfig cfg = ModelConfig::from_json(j);
  if (available_memory_bytes() > (uint64_t(96) << 30)) GTEST_SKIP() << "this machine could hold 96 GiB";
  const std::string msg = error_of([&] { Network net(cfg, 1); });
  EXPECT_NE(msg.find("(17179869184 in the grid table)"), std::string::npos) << msg;
  EXPECT_NE(msg.find("exceeding the memory available"), std::string::npos) << msg;
}

// An instantvnr-style sidecar claiming 10^12 voxels over a 64-byte file.
TEST(Limits, SidecarClaimingTeraVoxelsIsRefusedByTheFileSize) {
  const std::string dir = temp_dir("vnr_limits");
  write_text(dir + "/small2.raw", std::string(64, '\0'));
  write_text(dir + "/tera.json", R"({"file": "small2.raw", "dims": [10000, 10000, 10000], "dtype": "uint8"})");
  const std::string msg = error_of([&] { describe_volume(dir + "/tera.json"); });
  EXPECT_NE(msg.find("has 64 bytes, expected 1000000000000"), std::string::npos) << msg;
}

// A .vnr file with bytes appended (or cut) disagrees with the parameter count in its header.
TEST(Limits, ModelWhoseParametersDisagreeWithItsSizeIsRefused) {
  const std::string dir = temp_dir("vnr_limits");
  ASSERT_EQ(run("synth marschner-lobb --dims 12,12,12 -o " + dir + "/s.json").code, 0);
  ASSERT_EQ(run("train " + dir + "/s.json -o " + dir + "/s.vnr --config small --steps 2 -q --no-ssim").code, 0);
  std::string bytes = read_file(dir + "/s.vnr");
  write_text(dir + "/grown.vnr", bytes + std::string(1 << 20, '\1'));
  Result r = run("info " + dir + "/grown.vnr");
  EXPECT_NE(r.code, 0);
  EXPECT_EQ(count_lines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("header describes " + std::to_string(bytes.size()) + " bytes, file has " +
                       std::to_string(bytes.size() + (1 << 20))),
            std::string::npos)
      << r.err;
}

// Sets VNR_MEMORY_LIMIT for one test (and the `vnr` processes it starts), restoring it after.
struct MemoryLimit {
  explicit MemoryLimit(const char* limit) { ::setenv("VNR_MEMORY_LIMIT", limit, 1); }
  ~MemoryLimit() { ::unsetenv("VNR_MEMORY_LIMIT"); }
};

TEST(Limits, MemoryLimitFromTheEnvironmentCapsTheAvailableMemory) {
  const uint64_t unlimited = available_memory_bytes();
  {
    MemoryLimit limit("3MiB");
    EXPECT_EQ(available_memory_bytes(), std::min<uint64_t>(unlimited, 3 << 20));
  }
  MemoryLimit bad("lots");
  EXPECT_NE(error_of([] { available_memory_bytes(); }).find("VNR_MEMORY_LIMIT: invalid size 'lots'"), std::string::npos);
}

// With a 1 GiB limit the 96 GiB dense grid above is refused on any machine.
TEST(Limits, ParameterCountIsRefusedUnderAMemoryLimit) {
  MemoryLimit limit("1GiB");
  Json j = preset_config("small");
  j["encoding"] = {{"otype", "DenseGrid"}, {"n_levels", 1}, {"n_features_per_level", 8}, {"base_resolution", 1300}};
  const std::string msg = error_of([&] { Network net(ModelConfig::from_json(j), 1); });
  EXPECT_NE(msg.find("= 96.00 GiB exceeding the memory available (1.00 GiB)"), std::string::npos) << msg;
}

// A fuzzer's 2 KB BSON file whose damaged config falls back to a 16-million-parameter network: refused by
// the parameter count before that network is allocated (it took 0.9 s and 260 MB), so even a 64 MiB
// memory limit sees the count message, not the memory one.
TEST(Limits, ModelFileWithTooFewParametersIsRefusedBeforeTheNetworkExists) {
  MemoryLimit limit("64MiB");
  const std::string path = std::string(VNR_TEST_DATA_DIR) + "/fuzz/fuzz_bson_model/default_config_few_params.bson";
  const std::string msg = error_of([&] { load_model(path); });
  EXPECT_NE(msg.find("the file holds 768 parameters but its configuration needs 16363648"), std::string::npos) << msg;
}

// A model whose parameters fit (6 bytes each) but whose training state does not (16 more: gradient,
// Adam's two moments and step count) is refused before training allocates, naming the sizes.
TEST(Limits, TrainingStateIsCountedBeforeAllocating) {
  const std::string dir = temp_dir("vnr_limits_training");
  ASSERT_EQ(run("synth marschner-lobb --dims 12,12,12 -o " + dir + "/s.json").code, 0);
  Json j = preset_config("small");
  j["encoding"] = {{"otype", "HashGrid"}, {"n_levels", 8}, {"n_features_per_level", 2}, {"log2_hashmap_size", 19},
                   {"base_resolution", 16}};
  write_text(dir + "/big.json", j.dump());
  MemoryLimit limit("64MiB");  // 5.8 M parameters: 33 MiB as a network, 89 MiB more to train
  const Result r = run("train " + dir + "/s.json -o " + dir + "/s.vnr --config " + dir + "/big.json --steps 2 -q");
  EXPECT_NE(r.code, 0);
  EXPECT_EQ(count_lines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("exceeding the memory available (64.00 MiB)"), std::string::npos) << r.err;
}

// A .vnr header may claim dims up to 2^31 per axis; their product may wrap a 64-bit count (here to 0)
// or exceed what any loader accepts. Refused at load, naming the dims.
TEST(Limits, ModelWithHugeDimsIsRefusedAtLoad) {
  const std::string path = std::string(VNR_TEST_DATA_DIR) + "/fuzz/fuzz_vnr_decode/count_wraps_to_zero.vnr";
  const std::string msg = error_of([&] { load_model(path); });
  EXPECT_NE(msg.find("volume dims 4194304x2097152x2097152 = 1.845e+19 voxels exceed the limit of 2^40"),
            std::string::npos)
      << msg;
}

// dims 100000x100000x100 (1e12 voxels, within the load limit): decoding is refused before it allocates,
// through the API and through `vnr decode`, which leaves no output behind.
TEST(Limits, DecodeOfHugeDimsIsRefusedBeforeAllocating) {
  const std::string path = std::string(VNR_TEST_DATA_DIR) + "/fuzz/fuzz_vnr_decode/tera_voxels.vnr";
  MemoryLimit limit("1GiB");
  const Model m = load_model(path);
  ModelQuery query(m, Device::Cpu);
  const std::string msg = error_of([&] { query.decode(); });
  EXPECT_NE(msg.find("decoding 100000x100000x100 (100 z-slices at a time) needs 3.64 TiB of float32, exceeding the "
                     "memory available (1.00 GiB)"),
            std::string::npos)
      << msg;
  const std::string dir = temp_dir("vnr_limits_decode");
  const std::string one_slice = std::string(VNR_TEST_DATA_DIR) + "/fuzz/fuzz_vnr_decode/one_huge_slice.vnr";
  expect_error("decode " + one_slice + " -o " + dir + "/out.raw", "decoding 1048576x1048576x1 (1 z-slices");
  // --dims whose plane overflows a 64-bit product
  const std::string plain = std::string(VNR_TEST_DATA_DIR) + "/../../fuzz/corpus/fuzz_vnr_decode/plain.vnr";
  expect_error("decode " + plain + " --dims 9223372036854775807,2,1 -o " + dir + "/out.raw",
               "decoding 9223372036854775807x2x1 (1 z-slices at a time) needs 67108864.00 TiB");
  EXPECT_TRUE(std::filesystem::is_empty(dir));
}

}  // namespace
}  // namespace vnr::test
