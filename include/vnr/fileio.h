#pragma once
#include <cstdint>
#include <cstdio>
#include <string>
#include <string_view>

namespace vnr {

std::string read_file(const std::string& path);  // whole file; clear error if unreadable
uint64_t file_size(const std::string& path);     // clear error if missing
bool file_exists(const std::string& path);
std::string dirname_of(const std::string& path);  // "" for a bare file name
std::string join_path(const std::string& dir, const std::string& name);  // name if absolute
std::string basename_of(const std::string& path);      // the part after the last '/'
std::string extension_of(const std::string& path);     // lower-case, with the dot (".nrrd"); "" if none
std::string strip_extension(const std::string& path);  // path without its extension

// Writes a file atomically: data goes to "<path>.tmp-<pid>" in the same directory and is renamed
// over <path> on commit(), so readers never see a half-written file and a crash leaves the old
// file intact. Destroying an uncommitted AtomicFile removes the temporary.
class AtomicFile {
public:
  explicit AtomicFile(const std::string& path);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;
  void write(const void* data, size_t bytes);
  void write(std::string_view s) { write(s.data(), s.size()); }
  void commit();
  const std::string& path() const { return path_; }

private:
  std::string path_, tmp_;
  std::FILE* f_ = nullptr;
  int slot_ = -1;  // where tmp_ is registered for remove_pending_temporaries()
};

// Unlinks the temporaries of every AtomicFile not yet committed. Async-signal-safe: a SIGTERM/SIGINT
// handler calls it before the process dies, so a kill during a save leaves no partial file behind.
void remove_pending_temporaries();

void write_file_atomic(const std::string& path, std::string_view data);

uint32_t crc32_of(const void* data, size_t bytes, uint32_t crc = 0);

}  // namespace vnr
