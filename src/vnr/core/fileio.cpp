#include "vnr/fileio.h"
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>
#include <atomic>
#include <cerrno>
#include <cstring>
#include "vnr/error.h"
#include "vnr/json.h"

namespace vnr {

std::string read_file(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) fail("cannot open '{}': {}", path, std::strerror(errno));
  std::string out;
  char buf[1 << 16];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) out.append(buf, n);
  bool err = std::ferror(f);
  std::fclose(f);
  if (err) fail("cannot read '{}'", path);
  return out;
}

uint64_t file_size(const std::string& path) {
  struct stat st;
  if (::stat(path.c_str(), &st) != 0) fail("cannot open '{}': {}", path, std::strerror(errno));
  if (S_ISDIR(st.st_mode)) fail("'{}' is a directory, expected a file", path);
  return uint64_t(st.st_size);
}

bool file_exists(const std::string& path) {
  struct stat st;
  return ::stat(path.c_str(), &st) == 0;
}

std::string dirname_of(const std::string& path) {
  auto p = path.find_last_of('/');
  return p == std::string::npos ? std::string() : path.substr(0, p);
}

std::string join_path(const std::string& dir, const std::string& name) {
  if (dir.empty() || (!name.empty() && name[0] == '/')) return name;
  return dir + "/" + name;
}

std::string basename_of(const std::string& path) {
  size_t slash = path.find_last_of('/');
  return slash == std::string::npos ? path : path.substr(slash + 1);
}

namespace {
// Position of the extension's dot, or npos when the last path component has none.
size_t extension_dot(const std::string& path) {
  size_t slash = path.find_last_of('/');
  size_t dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return std::string::npos;
  return dot;
}
}  // namespace

std::string extension_of(const std::string& path) {
  size_t dot = extension_dot(path);
  return dot == std::string::npos ? std::string() : to_lower(path.substr(dot));
}

std::string strip_extension(const std::string& path) {
  size_t dot = extension_dot(path);
  return dot == std::string::npos ? path : path.substr(0, dot);
}

namespace {

// Fixed storage, so a signal handler can read it without allocating or locking. A slot is claimed
// (kWriting), filled, then published (kReady); the handler reads only published slots.
constexpr int kPendingSlots = 16;
constexpr size_t kPendingPathBytes = 4096;
enum PendingState : int { kFree = 0, kWriting = 1, kReady = 2 };
char g_pending_paths[kPendingSlots][kPendingPathBytes];
std::atomic<int> g_pending_state[kPendingSlots];

int register_pending(const std::string& tmp) {
  if (tmp.size() >= kPendingPathBytes) return -1;
  for (int i = 0; i < kPendingSlots; ++i) {
    int expected = kFree;
    if (g_pending_state[i].compare_exchange_strong(expected, kWriting)) {
      std::memcpy(g_pending_paths[i], tmp.c_str(), tmp.size() + 1);
      g_pending_state[i].store(kReady);
      return i;
    }
  }
  return -1;  // more concurrent saves than slots: that temporary is simply not cleaned on a signal
}

void unregister_pending(int slot) {
  if (slot >= 0) g_pending_state[slot].store(kFree);
}

}  // namespace

void remove_pending_temporaries() {
  for (int i = 0; i < kPendingSlots; ++i)
    if (g_pending_state[i].load() == kReady) ::unlink(g_pending_paths[i]);
}

AtomicFile::AtomicFile(const std::string& path) : path_(path) {
  tmp_ = path + ".tmp-" + std::to_string(::getpid());
  slot_ = register_pending(tmp_);
  f_ = std::fopen(tmp_.c_str(), "wb");
  if (!f_) {
    int e = errno;
    unregister_pending(slot_);
    fail("cannot write '{}': {}", path, std::strerror(e));
  }
}

AtomicFile::~AtomicFile() {
  if (f_) {
    std::fclose(f_);
    std::remove(tmp_.c_str());
  }
  unregister_pending(slot_);
}

void AtomicFile::write(const void* data, size_t bytes) {
  if (bytes && std::fwrite(data, 1, bytes, f_) != bytes)
    fail("cannot write '{}': {}", path_, std::strerror(errno));
}

void AtomicFile::commit() {
  if (std::fflush(f_) != 0 || ::fsync(fileno(f_)) != 0)
    fail("cannot write '{}': {}", path_, std::strerror(errno));
  const bool closed = std::fclose(f_) == 0;
  f_ = nullptr;
  if (!closed) {
    int e = errno;
    std::remove(tmp_.c_str());
    fail("cannot write '{}': {}", path_, std::strerror(e));
  }
  if (std::rename(tmp_.c_str(), path_.c_str()) != 0) {
    int e = errno;
    std::remove(tmp_.c_str());
    fail("cannot write '{}': {}", path_, std::strerror(e));
  }
}

void write_file_atomic(const std::string& path, std::string_view data) {
  AtomicFile f(path);
  f.write(data);
  f.commit();
}

uint32_t crc32_of(const void* data, size_t bytes, uint32_t crc) {
  const auto* p = static_cast<const Bytef*>(data);
  while (bytes > 0) {
    uInt chunk = bytes > (1u << 30) ? (1u << 30) : uInt(bytes);
    crc = uint32_t(::crc32(crc, p, chunk));
    p += chunk;
    bytes -= chunk;
  }
  return crc;
}

}  // namespace vnr
