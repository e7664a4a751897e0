// Helpers shared by the test executables (one per tests/test_*.cpp): temporary directories, small
// file writers, capturing vnr::Error messages, synthetic volumes, MLP model configs and running the
// `vnr` command line. Header-only; everything is inline and lives in vnr::test.
#pragma once

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>
#include <zlib.h>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <initializer_list>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <vector>
#include "vnr/dtype.h"
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/json.h"
#include "vnr/math.h"
#include "vnr/volume/volume.h"
#include "vnr/volume_writer.h"

// Expects `msg` to contain `sub`, printing the message when it does not.
#define EXPECT_HAS(msg, sub) EXPECT_NE((msg).find(sub), std::string::npos) << "message: " << (msg)

namespace vnr::test {

// ---- floats --------------------------------------------------------------------------------------

// The bit pattern of f, for bit-exact comparisons of floats (NaNs and signed zeros included).
inline uint32_t bits(float f) {
  uint32_t u;
  std::memcpy(&u, &f, 4);
  return u;
}

// The largest |a[i] - b[i]| over a (b at least as long).
template <typename A, typename B>
double max_abs_diff(const A& a, const B& b) {
  double e = 0;
  for (size_t i = 0; i < a.size(); ++i) e = std::max(e, std::fabs(double(a[i]) - double(b[i])));
  return e;
}

// ---- temporary directories ----------------------------------------------------------------------

// A fresh, empty directory for one test, removed with its contents when this goes out of scope:
// <TempDir>/<prefix>_<pid>_<n>_<test name>, so no two tests, and no two test processes running at
// once, ever share one.
class TmpDir {
public:
  explicit TmpDir(const std::string& prefix = "vnr") {
    static std::atomic<int> counter{0};
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    path_ = std::filesystem::path(::testing::TempDir()) /
            (prefix + "_" + std::to_string(::getpid()) + "_" + std::to_string(counter++) + "_" +
             (info ? info->name() : "outside_test"));
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~TmpDir() {
    std::error_code ignored;  // never throw from here: a test may leave a directory it cannot delete
    std::filesystem::remove_all(path_, ignored);
  }
  TmpDir(const TmpDir&) = delete;
  TmpDir& operator=(const TmpDir&) = delete;

  std::string operator/(const std::string& name) const { return (path_ / name).string(); }
  std::string str() const { return path_.string(); }

private:
  std::filesystem::path path_;
};

// One directory for the whole test process: <TempDir>/<prefix>_<pid>, emptied and created on the
// first call with that prefix, then kept. The pid keeps test executables running in parallel (and
// ctest's one process per test) apart.
inline std::string temp_dir(const std::string& prefix = "vnr") {
  static std::mutex mutex;
  static std::map<std::string, std::string> dirs;
  std::lock_guard<std::mutex> lock(mutex);
  auto [it, fresh] = dirs.try_emplace(prefix, ::testing::TempDir() + prefix + "_" + std::to_string(::getpid()));
  if (fresh) {
    std::filesystem::remove_all(it->second);
    std::filesystem::create_directories(it->second);
  }
  return it->second;
}

// ---- writing files ------------------------------------------------------------------------------

inline void write_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream f(path, std::ios::binary);
  f.write(bytes.data(), std::streamsize(bytes.size()));
}

// `n` bytes, all `fill`.
inline void write_bytes(const std::string& path, size_t n, unsigned char fill = 7) {
  write_bytes(path, std::string(n, char(fill)));
}

// Appends `bytes` as one gzip member (mode "ab" adds it after what the file holds).
inline void write_gzip(const std::string& path, const std::string& bytes, const char* mode = "wb") {
  gzFile g = gzopen(path.c_str(), mode);
  ASSERT_NE(g, nullptr);
  ASSERT_EQ(gzwrite(g, bytes.data(), unsigned(bytes.size())), int(bytes.size()));
  gzclose(g);
}

// Appends v converted to T, big endian when `big`.
template <typename T>
void append_value(std::string& out, double v, bool big) {
  T t = T(v);
  unsigned char b[sizeof(T)];
  std::memcpy(b, &t, sizeof(T));
  if (big) std::reverse(b, b + sizeof(T));
  out.append(reinterpret_cast<const char*>(b), sizeof(T));
}

// The bytes of `values` stored as dtype `t`.
inline std::string encode(DType t, const std::vector<double>& values, bool big = false) {
  std::string out;
  for (double v : values) {
    switch (t) {
      case DType::Int8: append_value<int8_t>(out, v, big); break;
      case DType::UInt8: append_value<uint8_t>(out, v, big); break;
      case DType::Int16: append_value<int16_t>(out, v, big); break;
      case DType::UInt16: append_value<uint16_t>(out, v, big); break;
      case DType::Int32: append_value<int32_t>(out, v, big); break;
      case DType::UInt32: append_value<uint32_t>(out, v, big); break;
      case DType::Float32: append_value<float>(out, v, big); break;
      case DType::Float64: append_value<double>(out, v, big); break;
    }
  }
  return out;
}

// ---- vnr::Error ---------------------------------------------------------------------------------

// The message of the vnr::Error `fn` throws; nullopt when it returns normally.
template <typename F>
std::optional<std::string> thrown_error(F&& fn) {
  try {
    fn();
  } catch (const Error& e) {
    return std::string(e.what());
  }
  return std::nullopt;
}

// The message of the vnr::Error `fn` throws; "" and a test failure when it throws none.
template <typename F>
std::string error_of(F&& fn) {
  if (std::optional<std::string> m = thrown_error(fn)) return *m;
  ADD_FAILURE() << "expected a vnr::Error";
  return "";
}

// error_of, and a test failure unless the message is one line.
template <typename F>
std::string one_line_error_of(F&& fn) {
  std::string m = error_of(fn);
  EXPECT_EQ(m.find('\n'), std::string::npos) << "message must be one line: " << m;
  return m;
}

// Expects `fn` to throw a one-line vnr::Error whose message contains every fragment.
template <typename F>
void expect_error(F&& fn, std::initializer_list<const char*> fragments) {
  std::optional<std::string> msg = thrown_error(fn);
  if (!msg) {
    ADD_FAILURE() << "expected vnr::Error containing '" << *fragments.begin() << "'";
    return;
  }
  for (const char* f : fragments) EXPECT_NE(msg->find(f), std::string::npos) << "message: " << *msg << "\nmissing: " << f;
  EXPECT_EQ(msg->find('\n'), std::string::npos) << "multi-line message: " << *msg;
}

// ---- volumes and models -------------------------------------------------------------------------

// A volume whose voxel (x, y, z) holds f at its cell centre ((x + 0.5) / dims.x, ...), x fastest;
// f gives normalised values (lo = 0, hi = 1).
inline Volume make_volume(Int3 dims, const std::function<float(float, float, float)>& f) {
  Volume v;
  v.dims = dims;
  v.data.resize(dims.count());
  for (int64_t z = 0; z < dims.z; ++z)
    for (int64_t y = 0; y < dims.y; ++y)
      for (int64_t x = 0; x < dims.x; ++x)
        v.data[x + dims.x * (y + dims.y * z)] =
            f((x + 0.5f) / float(dims.x), (y + 0.5f) / float(dims.y), (z + 0.5f) / float(dims.z));
  return v;
}

// A volume holding `values` (normalised, x fastest).
inline Volume make_volume(Int3 dims, const std::vector<float>& values) {
  Volume vol;
  vol.dims = dims;
  vol.data.assign(values.begin(), values.end());
  return vol;
}

// The Marschner-Lobb test field.
inline Volume synth(Int3 dims) {
  return make_volume(dims, [](float x, float y, float z) { return synth_value("marschner-lobb", x, y, z); });
}

// Two smooth blobs with empty space around them (macro-cells have cells to skip).
inline Volume blobs(Int3 dims) {
  return make_volume(dims, [](float x, float y, float z) {
    float a = (x - 0.3f) * (x - 0.3f) + (y - 0.35f) * (y - 0.35f) + (z - 0.3f) * (z - 0.3f);
    float b = (x - 0.7f) * (x - 0.7f) + (y - 0.6f) * (y - 0.6f) + (z - 0.65f) * (z - 0.65f);
    return std::max(std::exp(-a * 60.0f), 0.8f * std::exp(-b * 90.0f)) * (0.8f + 0.2f * std::sin(40 * x));
  });
}

// The world-space box of a volume: one unit per voxel.
inline Vec3f box_of(Int3 d) { return Vec3f{float(d.x), float(d.y), float(d.z)}; }
inline Vec3f box_of(const Volume& v) { return box_of(v.dims); }

// A model config: `encoding`, an MLP of `hidden` layers of `width` neurons (FullyFusedMLP for
// multiples of 16, CutlassMLP otherwise) and a loss.
inline Json mlp_model_config(Json encoding, int width, int hidden, const std::string& activation = "ReLU",
                             const std::string& output_activation = "None", const std::string& loss = "L2") {
  return Json{{"encoding", encoding},
              {"network",
               {{"otype", width % 16 == 0 ? "FullyFusedMLP" : "CutlassMLP"},
                {"n_neurons", width},
                {"n_hidden_layers", hidden},
                {"activation", activation},
                {"output_activation", output_activation}}},
              {"loss", {{"otype", loss}}}};
}

// A small hash-grid model config (4 levels of 2 features from resolution 4, 2^log2_table entries per
// level), an MLP of `hidden` layers of `width` neurons, L2 loss and Adam at learning rate 1e-2.
inline Json small_hash_config(int log2_table, int width, int hidden) {
  Json c = mlp_model_config({{"otype", "HashGrid"},
                             {"n_levels", 4},
                             {"n_features_per_level", 2},
                             {"log2_hashmap_size", log2_table},
                             {"base_resolution", 4}},
                            width, hidden);
  c["optimizer"] = {{"otype", "Adam"}, {"learning_rate", 1e-2}};
  return c;
}

// ---- the vnr command line -----------------------------------------------------------------------

struct Result {
  int code = -1;  // exit status; -1 when the process did not exit normally
  std::string out, err;
};

inline int count_lines(const std::string& s) {
  int n = 0;
  for (char c : s) n += c == '\n';
  return n;
}

#ifdef VNR_CLI_PATH
// Runs `vnr <args>` through the shell, stdout and stderr captured in files of this process's
// temp_dir("vnr_cli") (one run at a time per process).
inline Result run(const std::string& args) {
  const std::string dir = temp_dir("vnr_cli"), out = dir + "/stdout.txt", err = dir + "/stderr.txt";
  const std::string cmd = std::string(VNR_CLI_PATH) + " " + args + " >" + out + " 2>" + err;
  const int st = std::system(cmd.c_str());
  return Result{WIFEXITED(st) ? WEXITSTATUS(st) : -1, read_file(out), read_file(err)};
}

// Expects a failed run: non-zero exit, exactly one line on stderr, an "error" that contains `needle`.
inline void expect_error(const std::string& args, const std::string& needle) {
  Result r = run(args);
  EXPECT_NE(r.code, 0) << args;
  EXPECT_EQ(count_lines(r.err), 1) << args << "\n" << r.err;
  EXPECT_NE(r.err.find("error"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find(needle), std::string::npos) << args << "\n" << r.err;
}
#endif

}  // namespace vnr::test
