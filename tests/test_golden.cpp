// Behaviour pinned across refactors: the `vnr` command line's decoded volumes and rendered images for
// fixed seeds, two threads and fp32 arithmetic, compared byte for byte (FNV-1a of the output files)
// with what the build before the library-API refactor produced (tests/data/golden_outputs.json).
// VNR_GOLDEN_RECORD=1 writes that file instead of comparing (only when the arithmetic is meant to change).
#include <gtest/gtest.h>
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>
#include "vnr/json.h"
#include "test_support.h"

using namespace vnr;
using namespace vnr::test;

namespace {

std::string fnv1a_of_file(const std::string& path) {
  const std::string bytes = read_file(path);
  uint64_t h = 1469598103934665603ull;
  for (unsigned char c : bytes) h = (h ^ c) * 1099511628211ull;
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", (unsigned long long)h);
  return std::string(buf) + ":" + std::to_string(bytes.size());
}

const std::string kGoldenPath = std::string(VNR_TEST_DATA_DIR) + "/golden_outputs.json";

bool recording() {
  const char* r = std::getenv("VNR_GOLDEN_RECORD");
  return r && std::string(r) == "1";
}

// Runs `vnr args`, expects success.
void vnr_ok(const std::string& args) {
  Result r = run(args);
  ASSERT_EQ(r.code, 0) << args << "\n" << r.err;
}

class Golden : public ::testing::Test {
protected:
  static Json& recorded() {
    static Json j = [] {
      if (recording()) return Json::object();
      return parse_json_file(kGoldenPath);
    }();
    return j;
  }
  static void TearDownTestSuite() {
    if (!recording()) return;
    std::ofstream(kGoldenPath) << recorded().dump(2) << "\n";
  }
  void check(const std::string& key, const std::string& file) {
    const std::string h = fnv1a_of_file(file);
    if (recording()) {
      recorded()[key] = h;
      return;
    }
    ASSERT_TRUE(recorded().contains(key)) << key;
    EXPECT_EQ(recorded()[key].get<std::string>(), h) << key << " (" << file << ")";
  }
  const std::string d = temp_dir("vnr_golden");
  const std::string fixed = " --threads 2 --precision fp32 ";
};

TEST_F(Golden, TrainAndDecodeSmallPaperAndRatio) {
  vnr_ok("synth marschner-lobb --dims 24,20,16 -o " + d + "/ml.json --force");
  vnr_ok("train " + d + "/ml.json -o " + d + "/small.vnr --config small --steps 60 --batch 8192 --seed 3 -q" + fixed);
  vnr_ok("decode " + d + "/small.vnr -o " + d + "/small.raw --force -q" + fixed);
  check("train_small_decode", d + "/small.raw");
  vnr_ok("decode " + d + "/small.vnr -o " + d + "/small_up.raw --dims 37,29,11 --force -q" + fixed);
  check("train_small_decode_resampled", d + "/small_up.raw");
  vnr_ok("train " + d + "/ml.json -o " + d + "/paper.vnr --config paper --steps 12 --batch 4096 --seed 5 -q" + fixed);
  vnr_ok("decode " + d + "/paper.vnr -o " + d + "/paper.raw --force -q" + fixed);
  check("train_paper_decode", d + "/paper.raw");
  vnr_ok("train " + d + "/ml.json -o " + d + "/ratio.vnr --config small --target-ratio 4 --steps 30 --batch 4096 -q" +
         fixed);
  vnr_ok("decode " + d + "/ratio.vnr -o " + d + "/ratio.raw --force -q" + fixed);
  check("train_ratio_decode", d + "/ratio.raw");
  vnr_ok("train " + d + "/ml.json -o " + d + "/ooc.vnr --config small --sampler outofcore --memory-budget 16KiB " +
         "--block-dims 8,4,4 --steps 30 --batch 4096 --seed 9 -q" + fixed);
  vnr_ok("decode " + d + "/ooc.vnr -o " + d + "/ooc.raw --force -q" + fixed);
  check("train_outofcore_decode", d + "/ooc.raw");
}

TEST_F(Golden, RenderModelAndVolume) {
  vnr_ok("synth marschner-lobb --dims 24,20,16 -o " + d + "/ml.json --force");
  vnr_ok("train " + d + "/ml.json -o " + d + "/small.vnr --config small --steps 40 --batch 8192 --seed 3 -q" + fixed);
  for (const char* mode : {"raymarch", "shadow", "pathtrace"})
    for (const char* strategy : {"inshader", "streaming"})
      for (const char* input : {"small.vnr", "ml.json"}) {
        const std::string key = std::string("render_") + mode + "_" + strategy + "_" + input;
        const std::string out = d + "/" + key + ".pfm";
        vnr_ok("render " + d + "/" + input + " -o " + out + " --size 40x32 --orbit 30,20 --mode " + mode +
               " --strategy " + strategy + " --spp 2 --seed 7 -q" + fixed);
        check(key, out);
      }
  vnr_ok("render " + d + "/small.vnr -o " + d + "/grid_mc.pfm --size 40x32 --macrocells grid --volume " + d +
         "/ml.json --shade --spp 1 --strategy streaming -q" + fixed);  // the defaults before --spp auto and the cache
  check("render_network_grid_macrocells_shaded", d + "/grid_mc.pfm");
}

TEST_F(Golden, TimeSeriesWarmAndContinuous) {
  vnr_ok("synth noise --dims 16,16,12 --timesteps 3 -o " + d + "/series.json --force");
  vnr_ok("train " + d + "/series.json --timesteps all -o " + d + "/warm --config small --steps 20 --batch 4096 -q" +
         fixed);
  for (int t = 0; t < 3; ++t) {
    const std::string model = d + "/warm/t000" + std::to_string(t) + ".vnr";
    vnr_ok("decode " + model + " -o " + d + "/warm" + std::to_string(t) + ".raw --force -q" + fixed);
    check("series_warm_t" + std::to_string(t), d + "/warm" + std::to_string(t) + ".raw");
  }
  vnr_ok("train " + d + "/series.json --timesteps all --continuous --switch-every 10 -o " + d +
         "/cont --config small --batch 4096 -q" + fixed);
  for (int t = 0; t < 3; ++t) {
    vnr_ok("decode " + d + "/cont/t000" + std::to_string(t) + ".vnr -o " + d + "/cont.raw --force -q" + fixed);
    check("series_continuous_t" + std::to_string(t), d + "/cont.raw");
  }
}

}  // namespace

// A compact model written before context coding (codec quant-zstd: the ratio model of the test above,
// as the build of 2026-11-27 wrote it) decodes to exactly what that build decoded.
TEST_F(Golden, QuantZstdModelsOfEarlierBuildsDecodeAsBefore) {
  vnr_ok("decode " + std::string(VNR_TEST_DATA_DIR) + "/compact_quant_zstd.vnr -o " + d + "/old.raw --force -q" + fixed);
  check("decode_compact_quant_zstd", d + "/old.raw");
}
