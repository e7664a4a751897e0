// The fuzz targets' inputs replayed through the same library entry points (fuzz/*.cpp), without
// libFuzzer: every seed of fuzz/corpus/<target>/ is a valid file that loads, and every input a fuzzer
// once crashed on (tests/data/fuzz/<target>/) now gives one clear vnr::Error or loads fine.
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>
#include "test_support.h"
#include "vnr/model.h"
#include "vnr/model_config.h"
#include "vnr/scene.h"
#include "vnr/render/transfer_function.h"
#include "vnr/train/model.h"
#ifdef VNR_HAVE_VIEW
#include "view/protocol.h"
#endif

namespace fs = std::filesystem;
using namespace vnr;

namespace {

const fs::path kCorpusDir = fs::path(VNR_TEST_DATA_DIR) / ".." / ".." / "fuzz" / "corpus";
const fs::path kRegressionDir = fs::path(VNR_TEST_DATA_DIR) / "fuzz";

std::string read_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

void write_bytes(const fs::path& p, const std::string& bytes) {
  std::ofstream(p, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
}

// Loads a described volume when it is small, as the fuzz targets do, checking the values it gives.
void describe_and_load(const fs::path& path) {
  const VolumeDesc d = describe_volume(path.string());
  if (d.dims.count() > (1 << 16)) return;
  const Volume v = load_volume(d);
  ASSERT_EQ(v.data.size(), d.dims.count());
  for (float x : v.data) ASSERT_TRUE(x >= 0.0f && x <= 1.0f);
}

// One fuzz target: writes the input where its fuzz target does (beside the 4 KiB data files the
// descriptors name) and calls the same entry point.
using Runner = std::function<void(const std::string& bytes, const fs::path& dir, const std::string& name)>;

std::map<std::string, Runner> runners() {
  std::map<std::string, Runner> r;
  auto volume_file = [](const char* file) {
    return [file](const std::string& bytes, const fs::path& dir, const std::string&) {
      write_bytes(dir / file, bytes);
      describe_and_load(dir / file);
    };
  };
  r["fuzz_sidecar"] = volume_file("volume.json");
  r["fuzz_nrrd"] = volume_file("volume.nrrd");
  r["fuzz_nhdr"] = volume_file("volume.nhdr");
  r["fuzz_scene"] = [](const std::string& bytes, const fs::path& dir, const std::string&) {
    write_bytes(dir / "scene.json", bytes);
    const Scene s = load_scene((dir / "scene.json").string());
    if (s.has_volume) describe_and_load(dir / "scene.json");
  };
  r["fuzz_tf"] = [](const std::string& bytes, const fs::path&, const std::string&) {
    const TransferFunction tf = tf_from_json(parse_json_text(bytes, "input"), "input");
    const TransferFunction back = tf_from_json(tf_to_instantvnr_json(tf), "round trip");
    EXPECT_EQ(back.table.size(), tf.table.size());
  };
  r["fuzz_config"] = [](const std::string& bytes, const fs::path&, const std::string&) {
    ModelConfig::from_json(parse_json_text(bytes, "input"));
  };
  auto model_file = [](const char* file) {
    return [file](const std::string& bytes, const fs::path& dir, const std::string&) {
      write_bytes(dir / file, bytes);
      const Model m = load_model((dir / file).string());
      EXPECT_GT(m.net->n_params(), 0u);
    };
  };
  r["fuzz_vnr_model"] = model_file("model.vnr");
  r["fuzz_bson_model"] = model_file("params.bson");
  r["fuzz_vnr_decode"] = [](const std::string& bytes, const fs::path& dir, const std::string&) {
    write_bytes(dir / "model.vnr", bytes);
    const Model m = load_model((dir / "model.vnr").string());
    ModelQuery query(m, Device::Cpu);
    const Volume v = query.decode();
    ASSERT_EQ(v.data.size(), m.dims.count());
    // The decode's last voxel is the network at that voxel's centre.
    const float centre[3] = {float((m.dims.x - 0.5) / m.dims.x), float((m.dims.y - 0.5) / m.dims.y),
                             float((m.dims.z - 0.5) / m.dims.z)};
    float at_centre = 0;
    query.points(centre, 1, &at_centre);
    EXPECT_NEAR(v.data.back(), at_centre, 1e-5);
  };
#ifdef VNR_HAVE_VIEW
  r["fuzz_viewer_message"] = [](const std::string& bytes, const fs::path&, const std::string& name) {
    if (name.ends_with(".bin")) view::split_frame_message(bytes);
    else view::parse_client_message(bytes);
  };
#endif
  return r;
}

std::vector<fs::path> files_in(const fs::path& dir) {
  std::vector<fs::path> files;
  if (fs::is_directory(dir))
    for (const auto& e : fs::directory_iterator(dir)) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  return files;
}

// A scratch folder holding the data files the descriptors name (as fuzz/fuzz_support.h's targets do).
void write_data_files(const fs::path& dir) {
  std::string bytes(4096, '\0');
  for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = char(uint8_t(i * 7));
  write_bytes(dir / "data.raw", bytes);
  write_bytes(dir / "t1.raw", bytes);
}

}  // namespace

TEST(FuzzSeeds, EverySeedIsAValidFileThatLoads) {
  size_t n = 0;
  for (const auto& [target, run] : runners()) {
    for (const fs::path& seed : files_in(kCorpusDir / target)) {
      test::TmpDir dir("fuzz_seed");
      write_data_files(fs::path(dir.str()));
      SCOPED_TRACE(target + "/" + seed.filename().string());
      try {
        run(read_bytes(seed), fs::path(dir.str()), seed.filename().string());
      } catch (const Error& e) {
        ADD_FAILURE() << "seed refused: " << e.what();
      }
      ++n;
    }
  }
  EXPECT_GE(n, 20u);  // every target has seeds
}

TEST(FuzzRegressions, EveryFoundInputGivesOneClearErrorOrLoads) {
  for (const auto& [target, run] : runners()) {
    for (const fs::path& input : files_in(kRegressionDir / target)) {
      test::TmpDir dir("fuzz_regression");
      write_data_files(fs::path(dir.str()));
      SCOPED_TRACE(target + "/" + input.filename().string());
      try {
        run(read_bytes(input), fs::path(dir.str()), input.filename().string());
      } catch (const Error& e) {
        const std::string msg = e.what();
        EXPECT_FALSE(msg.empty());
        EXPECT_EQ(msg.find('\n'), std::string::npos) << "one line: " << msg;
      }
    }
  }
}
