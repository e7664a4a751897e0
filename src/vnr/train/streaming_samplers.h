#pragma once
// Samplers for volumes that are not in memory (paper, "Out-of-Core Sampling").
#include <condition_variable>
#include <exception>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>
#include "vnr/core/brick_box.h"
#include "vnr/memory.h"
#include "vnr/train/sampler.h"
#include "vnr/volume/raw_access.h"

namespace vnr {

struct OutOfCoreOptions {
  uint64_t memory_budget = uint64_t(1) << 30;  // bytes: blocks in use + blocks being loaded + buffers
  int64_t blocks = 0;   // R, blocks in the buffer; 0 = the paper's 65,536, scaled down to the budget
  int64_t refresh = 0;  // S, blocks replaced per step; 0 = default_refresh(R): R/4, at most 1,024
  Int3 block_dims{0, 0, 0};  // interior voxels of a block; 0 = default_block_dims()
  int io_threads = 16;       // reader threads (each blocks in pread; many keep the disk queue full)
  std::function<void(double fraction)> fill_progress;  // during the initial fill
  // Empty: the whole volume. Else only these voxels of the file (a brick's trained box) are sampled
  // and read, as if the box were the volume: coordinates are normalised to the box and ghost voxels
  // beyond its faces repeat its edge voxels (as a volume loaded from the box would).
  Box3 region;
};

// Interior size of a block when none is given: 256 voxels along x (rows are contiguous in the
// file, so long rows mean few reads; short file rows are read several at a time) and equal y/z extents
// such that a block holds about 64 KiB of source data, as in the paper; clamped to the volume.
Int3 default_block_dims(Int3 volume_dims, DType dtype);

// The paper's random block buffer. R blocks of the volume (each stored normalised with one layer of
// ghost voxels, so trilinear interpolation near a block's faces reads the true neighbours) are kept
// in memory; every step, S of them are replaced by randomly chosen blocks that reader threads load
// while the step trains. A sample picks a random block of the buffer and a random voxel in it,
// jitters it by up to half a voxel and interpolates the target exactly as the in-core lookup does.
//
// Deterministic for a seed: the blocks chosen at step s are swapped in at the start of step s + 1,
// waiting for the reads if they are not done, so I/O timing never changes what is sampled.
class OutOfCoreSampler : public Sampler {
public:
  OutOfCoreSampler(std::shared_ptr<const RawVolumeFile> file, uint64_t seed, const OutOfCoreOptions& opts);
  ~OutOfCoreSampler() override;
  void begin_step(uint64_t step) override;
  void sample(uint64_t seed, uint64_t step, uint64_t chunk, int n, float* x, float* y, float* z,
              float* target) const override;

  static constexpr int64_t kMaxDefaultRefresh = 1024;  // the paper's S
  static int64_t default_refresh(int64_t blocks);     // S when --refresh is not given

  int64_t blocks() const { return R_; }
  Int3 dims() const { return dims_; }          // of the sampled region
  int64_t volume_blocks() const { return n_blocks_; }  // blocks the volume is divided into
  // Fraction of the volume's voxels the buffer holds at a time (block interiors, within the volume).
  double resident_fraction() const;
  // Expected fraction of the volume's blocks loaded at least once after `steps` steps:
  // 1 - exp(-(R + S * steps) / volume_blocks) (blocks are drawn uniformly with replacement).
  double expected_coverage(int64_t steps) const;
  int64_t refresh() const { return S_; }
  Int3 block_dims() const { return bd_; }
  uint64_t bytes_held() const;     // everything this sampler allocated (≤ the budget)
  double fill_seconds() const { return fill_seconds_; }
  double io_wait_seconds() const { return io_wait_seconds_; }  // time begin_step waited for reads
  uint64_t blocks_loaded() const { return blocks_loaded_; }
  const RawVolumeFile& file() const { return *file_; }

private:
  struct Job {
    int64_t slot;     // buffer slot the block replaces
    int64_t block;    // block index in the volume's block grid
    int32_t storage;  // storage the block is read into
  };
  Int3 block_origin(int64_t block) const;
  void run_jobs(std::vector<Job>& jobs);  // hands jobs to the readers (returns at once)
  void wait_jobs();                        // rethrows a reader's error
  void reader_loop(int thread);
  void fill_buffer(const OutOfCoreOptions& opts);  // the initial R blocks
  void stop_readers();
  void read_block(Int3 origin, float* out, int thread);  // a stored block whose first ghost is `origin`

  std::shared_ptr<const RawVolumeFile> file_;
  uint64_t seed_;
  Int3 dims_, bd_, stored_, grid_;  // region, block interior, block with ghosts, blocks per axis
  Int3 origin_{0, 0, 0};            // of the region in the file
  bool in_region_ = false;          // a region smaller than the file: block sizes shrink to fit it
  int64_t n_blocks_ = 0, R_ = 0, S_ = 0, block_floats_ = 0;
  big_vector<float> storage_;              // (R + S) stored blocks
  std::vector<Int3> storage_origin_;       // interior origin of the block in each storage
  std::vector<int32_t> slot_storage_;      // slot -> storage
  std::vector<int32_t> spare_;             // S storages being loaded (not referenced by slots)
  std::vector<Job> pending_;               // reads issued at the previous step
  double fill_seconds_ = 0, io_wait_seconds_ = 0;
  uint64_t blocks_loaded_ = 0;

  // Reader pool.
  std::vector<std::thread> readers_;
  std::vector<std::vector<unsigned char>> scratch_;
  std::mutex mu_;
  std::condition_variable work_cv_, done_cv_;
  std::vector<Job>* jobs_ = nullptr;
  size_t next_job_ = 0, jobs_done_ = 0;
  bool stop_ = false;
  std::exception_ptr error_;
};

// The baseline the paper compares with: uniform random coordinates (the in-core sampler's), targets
// read through a memory map of the file, so every sample may fault pages in from disk.
class MmapSampler : public Sampler {
public:
  explicit MmapSampler(std::shared_ptr<const MappedVolume> volume);
  void begin_step(uint64_t step) override;
  void sample(uint64_t seed, uint64_t step, uint64_t chunk, int n, float* x, float* y, float* z,
              float* target) const override;

private:
  std::shared_ptr<const MappedVolume> vol_;
};

}  // namespace vnr
