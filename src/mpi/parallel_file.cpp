#include "mpi/parallel_file.h"
#include <fcntl.h>
#include <unistd.h>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include "mpi/comm.h"
#include "vnr/error.h"

namespace vnr::mpi {

ParallelFile::ParallelFile(const std::string& path, uint64_t bytes) : path_(path), bytes_(bytes) {
  tmp_ = broadcast(path + ".tmp-mpi-" + std::to_string(::getpid()), 0);
  agree(fmt::format("to create '{}'", path), [&] {
    if (rank() != 0) return;
    const int fd = ::open(tmp_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd < 0) fail("cannot create '{}': {}", tmp_, std::strerror(errno));
    // Full size up front: every rank writes inside it, and a full disk shows here rather than later.
    const int rc = bytes > 0 ? ::posix_fallocate(fd, 0, off_t(bytes)) : 0;
    ::close(fd);
    if (rc != 0 && ::truncate(tmp_.c_str(), off_t(bytes)) != 0) {
      ::unlink(tmp_.c_str());
      fail("cannot make '{}' {} bytes long: {}", tmp_, bytes, std::strerror(rc));
    }
  });
  agree(fmt::format("to open '{}'", tmp_), [&] {
    fd_ = ::open(tmp_.c_str(), O_WRONLY);
    if (fd_ < 0) fail("cannot open '{}' (is its directory on a file system every rank sees?): {}", tmp_, std::strerror(errno));
  });
}

ParallelFile::~ParallelFile() {
  if (fd_ >= 0) ::close(fd_);
  if (!committed_ && rank() == 0) ::unlink(tmp_.c_str());
}

void ParallelFile::write_at(uint64_t offset, const void* data, size_t bytes) {
  if (offset + bytes > bytes_) fail("'{}': a write of {} bytes at {} passes the end ({} bytes)", path_, bytes, offset, bytes_);
  const char* p = static_cast<const char*>(data);
  while (bytes > 0) {
    const ssize_t n = ::pwrite(fd_, p, bytes, off_t(offset));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) fail("cannot write '{}': {}", tmp_, std::strerror(n < 0 ? errno : ENOSPC));
    p += n, offset += uint64_t(n), bytes -= size_t(n);
  }
}

void ParallelFile::commit() {
  agree(fmt::format("to write '{}'", path_), [&] {
    if (::fsync(fd_) != 0) fail("cannot write '{}': {}", tmp_, std::strerror(errno));
  });
  ::close(fd_);
  fd_ = -1;
  agree(fmt::format("to rename '{}'", tmp_), [&] {
    if (rank() == 0 && std::rename(tmp_.c_str(), path_.c_str()) != 0)
      fail("cannot rename '{}' to '{}': {}", tmp_, path_, std::strerror(errno));
  });
  committed_ = true;
}

}  // namespace vnr::mpi
