// Faults while the vnr CLI writes or trains: a full disk (RLIMIT_FSIZE), SIGTERM/SIGINT at several
// points of `vnr train`, a volume file truncated under out-of-core training. In every case: one clear
// error line, the previous file intact (byte-equal) or the new one complete, and no temporaries left.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#include <chrono>
#include <csignal>
#include <filesystem>
#include <sstream>
#include <thread>
#include "test_support.h"
#include "vnr/fileio.h"

namespace vnr::test {
namespace {

namespace fs = std::filesystem;

struct Child {
  pid_t pid = -1;
  std::string err_path;
};

// Starts `vnr args...` with stderr to a file; fsize_limit > 0 caps the bytes it may write per file
// (SIGXFSZ ignored unless xfsz_default, so the write fails with EFBIG as on a full disk).
Child spawn(const std::string& args, const std::string& dir, rlim_t fsize_limit = 0, bool xfsz_default = false) {
  Child c;
  c.err_path = dir + "/child_stderr.txt";
  std::vector<std::string> words;
  std::istringstream in(args);
  for (std::string w; in >> w;) words.push_back(w);
  c.pid = ::fork();
  if (c.pid == 0) {
    int fd = ::open(c.err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    int null_fd = ::open("/dev/null", O_WRONLY);
    ::dup2(fd, 2);
    ::dup2(null_fd, 1);
    if (fsize_limit) {
      std::signal(SIGXFSZ, xfsz_default ? SIG_DFL : SIG_IGN);
      rlimit r{fsize_limit, fsize_limit};
      ::setrlimit(RLIMIT_FSIZE, &r);
    }
    std::vector<char*> argv{const_cast<char*>(VNR_CLI_PATH)};
    for (std::string& w : words) argv.push_back(w.data());
    argv.push_back(nullptr);
    ::execv(VNR_CLI_PATH, argv.data());
    ::_exit(127);
  }
  return c;
}

int wait_status(const Child& c) {
  int st = 0;
  ::waitpid(c.pid, &st, 0);
  return st;
}

std::string bytes_of(const std::string& path) { return fs::exists(path) ? read_file(path) : std::string(); }

// Files in dir whose name holds ".tmp-" (AtomicFile's temporaries).
std::vector<std::string> temporaries_in(const std::string& dir) {
  std::vector<std::string> t;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().filename().string().find(".tmp-") != std::string::npos) t.push_back(e.path().string());
  return t;
}

void sleep_ms(int ms) { std::this_thread::sleep_for(std::chrono::milliseconds(ms)); }

// Waits until the child catches `sig` (its SigCgt mask in /proc), i.e. main() has installed vnr's
// handler: a signal before that point is the kernel's default action, which no program can change.
void wait_for_handler(pid_t pid, int sig) {
  const uint64_t bit = uint64_t(1) << (sig - 1);
  for (int i = 0; i < 3000; ++i) {
    std::istringstream status(read_file("/proc/" + std::to_string(pid) + "/status"));
    for (std::string line; std::getline(status, line);)
      if (line.rfind("SigCgt:", 0) == 0 && (std::stoull(line.substr(7), nullptr, 16) & bit)) return;
    sleep_ms(1);
  }
  FAIL() << "vnr never installed a handler for signal " << sig;
}

// Training has begun once its first checkpoint replaced the previous model (up to 60 s on a busy machine).
void wait_for_first_checkpoint(const std::string& model, const std::string& previous) {
  for (int i = 0; i < 600 && bytes_of(model) == previous; ++i) sleep_ms(100);
  ASSERT_NE(bytes_of(model), previous) << "no checkpoint within 60 s";
}

class Faults : public ::testing::Test {
protected:
  void SetUp() override {
    dir = temp_dir("vnr_faults") + "/" + ::testing::UnitTest::GetInstance()->current_test_info()->name();
    fs::remove_all(dir);
    fs::create_directories(dir);
    ASSERT_EQ(run("synth marschner-lobb --dims 32,32,32 -o " + dir + "/ml.json").code, 0);
    ASSERT_EQ(run("train " + dir + "/ml.json -o " + dir + "/m.vnr --config small --steps 10 --batch 4096 -q --no-ssim")
                  .code,
              0);
    previous_model = read_file(dir + "/m.vnr");
  }
  std::string long_train() const {
    return "train " + dir + "/ml.json -o " + dir + "/m.vnr --config small --seconds 60 --batch 4096 -q --no-ssim";
  }
  std::string dir, previous_model;
};

// xfsz_default: as under a shell's `ulimit -f`, where SIGXFSZ would kill the process mid-write.
void expect_full_disk_keeps_the_model(const std::string& dir, const std::string& previous_model, bool xfsz_default) {
  Child c = spawn("train " + dir + "/ml.json -o " + dir + "/m.vnr --config small --steps 10 --batch 4096 --seed 7 -q "
                  "--no-ssim",
                  dir, 4096, xfsz_default);
  const int st = wait_status(c);
  ASSERT_TRUE(WIFEXITED(st));
  EXPECT_NE(WEXITSTATUS(st), 0);
  const std::string err = read_file(c.err_path);
  EXPECT_EQ(count_lines(err), 1) << err;
  EXPECT_NE(err.find("cannot write '" + dir + "/m.vnr'"), std::string::npos) << err;
  EXPECT_NE(err.find("File too large"), std::string::npos) << err;
  EXPECT_EQ(read_file(dir + "/m.vnr"), previous_model);
  EXPECT_TRUE(temporaries_in(dir).empty());
}

TEST_F(Faults, FullDiskDuringModelSaveKeepsThePreviousModel) { expect_full_disk_keeps_the_model(dir, previous_model, false); }

TEST_F(Faults, FileSizeLimitWithDefaultSigxfszKeepsThePreviousModel) {
  expect_full_disk_keeps_the_model(dir, previous_model, true);
}

TEST_F(Faults, FullDiskDuringDecodeKeepsThePreviousOutput) {
  ASSERT_EQ(run("decode " + dir + "/m.vnr -o " + dir + "/out.raw -q").code, 0);
  const std::string previous_raw = read_file(dir + "/out.raw"), previous_json = bytes_of(dir + "/out.json");
  ASSERT_GT(previous_raw.size(), 4096u);
  Child c = spawn("decode " + dir + "/m.vnr -o " + dir + "/out.raw --force -q", dir, 4096);
  const int st = wait_status(c);
  ASSERT_TRUE(WIFEXITED(st));
  EXPECT_NE(WEXITSTATUS(st), 0);
  const std::string err = read_file(c.err_path);
  EXPECT_EQ(count_lines(err), 1) << err;
  EXPECT_NE(err.find("out.raw"), std::string::npos) << err;
  EXPECT_NE(err.find("File too large"), std::string::npos) << err;
  EXPECT_EQ(read_file(dir + "/out.raw"), previous_raw);
  EXPECT_EQ(bytes_of(dir + "/out.json"), previous_json);
  EXPECT_TRUE(temporaries_in(dir).empty());
}

// One signal mid-training stops after the current step and saves a complete model (exit 0).
void expect_graceful_stop(const std::string& dir, const Child& c, const std::string& previous_model, int sig) {
  wait_for_first_checkpoint(dir + "/m.vnr", previous_model);
  sleep_ms(200);
  ASSERT_EQ(::kill(c.pid, sig), 0);
  const int st = wait_status(c);
  ASSERT_TRUE(WIFEXITED(st)) << "signalled: " << WTERMSIG(st);
  EXPECT_EQ(WEXITSTATUS(st), 0);
  const std::string err = read_file(c.err_path);
  EXPECT_EQ(count_lines(err), 1) << err;
  EXPECT_NE(err.find("interrupted after"), std::string::npos) << err;
  Result info = run("info " + dir + "/m.vnr");
  EXPECT_EQ(info.code, 0) << info.err;
  EXPECT_TRUE(temporaries_in(dir).empty());
}

TEST_F(Faults, SigtermMidTrainingSavesTheModel) {
  Child c = spawn(long_train() + " --checkpoint-every 50", dir);
  expect_graceful_stop(dir, c, previous_model, SIGTERM);
  EXPECT_NE(read_file(dir + "/m.vnr"), previous_model);
}

TEST_F(Faults, SigintMidTrainingSavesTheModel) {
  Child c = spawn(long_train() + " --checkpoint-every 50", dir);
  expect_graceful_stop(dir, c, previous_model, SIGINT);
  EXPECT_NE(read_file(dir + "/m.vnr"), previous_model);
}

// A time series stops the same way on SIGTERM: the timestep in training is saved, the series ends there.
TEST_F(Faults, SigtermDuringASeriesSavesTheCurrentTimestep) {
  ASSERT_EQ(run("synth marschner-lobb --dims 24,24,24 --timesteps 3 -o " + dir + "/ts.json").code, 0);
  Child c = spawn("train " + dir + "/ts.json --timesteps all -o " + dir + "/series --config small --seconds 30 "
                  "--batch 4096 -q --no-ssim",
                  dir);
  for (int i = 0; i < 600 && !fs::exists(dir + "/series"); ++i) sleep_ms(100);
  sleep_ms(1500);  // past loading the first timestep
  ASSERT_EQ(::kill(c.pid, SIGTERM), 0);
  const int st = wait_status(c);
  const std::string err = read_file(c.err_path);
  ASSERT_TRUE(WIFEXITED(st)) << err;
  EXPECT_EQ(WEXITSTATUS(st), 0);
  EXPECT_EQ(count_lines(err), 1) << err;
  EXPECT_NE(err.find("interrupted: stopped after timestep 0"), std::string::npos) << err;
  EXPECT_EQ(run("info " + dir + "/series/t0000.vnr").code, 0);
  EXPECT_FALSE(fs::exists(dir + "/series/t0001.vnr"));
  EXPECT_TRUE(temporaries_in(dir + "/series").empty());
}

// Whatever a signal interrupts, the model file is the previous one or a complete new one, and no
// temporary is left; a run killed by the signal says so in one error line (after the note of the first
// signal, when it came mid-training).
void expect_nothing_lost(const std::string& dir, const Child& c, const std::string& previous_model, int sig) {
  const int st = wait_status(c);
  const std::string err = read_file(c.err_path);
  if (WIFSIGNALED(st)) {
    EXPECT_EQ(WTERMSIG(st), sig);
    EXPECT_LE(count_lines(err), 2) << err;
    EXPECT_EQ(err.find("error"), err.rfind("error")) << err;
    EXPECT_NE(err.find("unfinished output discarded"), std::string::npos) << err;
  } else {
    EXPECT_TRUE(WIFEXITED(st) && WEXITSTATUS(st) == 0) << err;
  }
  if (read_file(dir + "/m.vnr") != previous_model) EXPECT_EQ(run("info " + dir + "/m.vnr").code, 0);
  EXPECT_TRUE(temporaries_in(dir).empty());
}

TEST_F(Faults, SignalsWhileLoadingLoseNothing) {
  for (int sig : {SIGTERM, SIGINT}) {
    Child c = spawn(long_train(), dir);
    wait_for_handler(c.pid, sig);
    sleep_ms(20);  // into loading the volume
    ASSERT_EQ(::kill(c.pid, sig), 0);
    expect_nothing_lost(dir, c, previous_model, sig);
  }
}

// A second signal right after the first lands in the evaluation or the final save: the process exits
// at once, discarding the unfinished model.
TEST_F(Faults, SecondSignalDuringTheFinalSaveLosesNothing) {
  for (int sig : {SIGTERM, SIGINT})
    for (int gap_ms : {0, 20, 100}) {
      Child c = spawn(long_train(), dir);
      sleep_ms(1500);
      ASSERT_EQ(::kill(c.pid, sig), 0);
      sleep_ms(gap_ms);
      ::kill(c.pid, sig);
      expect_nothing_lost(dir, c, previous_model, sig);
    }
}

TEST_F(Faults, VolumeTruncatedUnderOutOfCoreTrainingKeepsTheLastModel) {
  const std::string raw = dir + "/big.raw";
  ASSERT_EQ(run("synth noise --dims 64,64,64 -o " + dir + "/big.json").code, 0);
  ASSERT_TRUE(fs::exists(raw)) << "synth wrote no big.raw";
  Child c = spawn("train " + dir + "/big.json -o " + dir + "/m.vnr --config small --seconds 60 --batch 4096 -q "
                  "--no-ssim --sampler outofcore --memory-budget 256KiB --checkpoint-every 20",
                  dir);
  wait_for_first_checkpoint(dir + "/m.vnr", previous_model);
  fs::resize_file(raw, fs::file_size(raw) / 2);
  const int st = wait_status(c);
  const std::string err = read_file(c.err_path);
  ASSERT_TRUE(WIFEXITED(st)) << err;
  EXPECT_NE(WEXITSTATUS(st), 0);
  EXPECT_EQ(count_lines(err), 1) << err;
  EXPECT_NE(err.find(raw), std::string::npos) << err;
  Result info = run("info " + dir + "/m.vnr");
  EXPECT_EQ(info.code, 0) << info.err;
  EXPECT_NE(info.out.find("changed size during training"), std::string::npos) << info.out;  // the model says why
  EXPECT_TRUE(temporaries_in(dir).empty());
}

// What the CLI's signal handler relies on: an unfinished AtomicFile's temporary is removed, a committed
// file is left alone.
TEST(PendingTemporaries, RemovesOnlyUnfinishedTemporaries) {
  const std::string dir = temp_dir("vnr_faults") + "/pending";
  fs::remove_all(dir);
  fs::create_directories(dir);
  {
    AtomicFile done(dir + "/done.bin");
    done.write("kept");
    done.commit();
    AtomicFile unfinished(dir + "/unfinished.bin");
    unfinished.write("partial");
    ASSERT_EQ(temporaries_in(dir).size(), 1u);
    remove_pending_temporaries();
    EXPECT_TRUE(temporaries_in(dir).empty());
  }
  EXPECT_EQ(read_file(dir + "/done.bin"), "kept");
  EXPECT_FALSE(fs::exists(dir + "/unfinished.bin"));
}

}  // namespace
}  // namespace vnr::test
