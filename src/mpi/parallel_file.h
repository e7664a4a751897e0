#pragma once
// One output file written by all ranks at once, each at its own offsets (pwrite), and committed
// atomically: rank 0 creates "<path>.tmp-mpi-<pid>" at its full size, every rank writes its parts,
// and after all ranks have synced their writes rank 0 renames it over path. A job that fails (or an
// object destroyed before commit) removes the temporary, so path is either the old file or the whole
// new one. The directory must be one that every rank sees (a shared file system across nodes).
#include <cstdint>
#include <string>

namespace vnr::mpi {

class ParallelFile {
public:
  // Collective.
  ParallelFile(const std::string& path, uint64_t bytes);
  ~ParallelFile();  // not collective: each rank closes; rank 0 removes an uncommitted temporary
  ParallelFile(const ParallelFile&) = delete;
  ParallelFile& operator=(const ParallelFile&) = delete;

  // Writes bytes at offset (within the size given at creation); retries short writes.
  void write_at(uint64_t offset, const void* data, size_t bytes);
  // Collective: every rank's writes reach the disk, then rank 0 renames. A failing rank makes every
  // rank throw (agree()).
  void commit();

  const std::string& temporary_path() const { return tmp_; }

private:
  std::string path_, tmp_;
  uint64_t bytes_ = 0;
  int fd_ = -1;
  bool committed_ = false;
};

}  // namespace vnr::mpi
