// Hostile headers: a volume that claims 10^12 voxels, a config with a 2^40-entry table, a model whose
// parameter bytes disagree with its file size. Each is refused before any large allocation, with the
// sizes in the message.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#include <zlib.h>
#include <fstream>
#include "test_support.h"
#include "vnr/core/error.h"
#include "vnr/core/units.h"
#include "vnr/nn/config.h"
#include "vnr/nn/network.h"
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

}  // namespace
}  // namespace vnr::test
