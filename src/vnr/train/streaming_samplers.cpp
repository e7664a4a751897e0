#include "vnr/train/streaming_samplers.h"
#include <signal.h>
#include <unistd.h>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include "vnr/error.h"

namespace vnr {

Int3 default_block_dims(Int3 d, DType dtype) {
  const double source_bytes = 64.0 * 1024;
  const int64_t bx = std::min<int64_t>(256, d.x);
  int64_t b = std::llround(std::sqrt(source_bytes / double(dtype_size(dtype)) / double(bx)));
  b = std::max<int64_t>(b, 1);
  return Int3{bx, std::min<int64_t>(b, d.y), std::min<int64_t>(b, d.z)};
}

// S = R/4, at most the paper's 1,024. The paper's R/64 turns a small buffer over too slowly: a short
// run never sees much of the volume, and the optimiser chases the resident blocks
// (docs/benchmarks.md "Out-of-core training"). The cap keeps the reads per step
// at the paper's ~64 MiB when the buffer is large.
int64_t OutOfCoreSampler::default_refresh(int64_t blocks) {
  return std::clamp<int64_t>(blocks / 4, 1, kMaxDefaultRefresh);
}

OutOfCoreSampler::OutOfCoreSampler(std::shared_ptr<const RawVolumeFile> file, uint64_t seed,
                                   const OutOfCoreOptions& opts)
    : file_(std::move(file)), seed_(seed), dims_(file_->dims()) {
  if (!opts.region.empty()) {
    const Box3 whole{{0, 0, 0}, dims_};
    if (!(intersect(opts.region, whole) == opts.region))
      fail("region x {}..{}, y {}..{}, z {}..{} is not inside the volume {}x{}x{}", opts.region.lo.x, opts.region.hi.x,
           opts.region.lo.y, opts.region.hi.y, opts.region.lo.z, opts.region.hi.z, dims_.x, dims_.y, dims_.z);
    in_region_ = !(opts.region == whole);
    origin_ = opts.region.lo;
    dims_ = opts.region.size();
  }
  bd_ = opts.block_dims.x > 0 ? opts.block_dims : default_block_dims(dims_, file_->desc().dtype);
  // One --block-dims serves every brick of a multi-brick model: a brick narrower than a block gets blocks
  // as wide as itself.
  if (in_region_) bd_ = Int3{std::min(bd_.x, dims_.x), std::min(bd_.y, dims_.y), std::min(bd_.z, dims_.z)};
  for (int a = 0; a < 3; ++a)
    if (bd_[a] <= 0 || bd_[a] > dims_[a])
      fail("block size {}x{}x{} does not fit the volume {}x{}x{}", bd_.x, bd_.y, bd_.z, dims_.x, dims_.y, dims_.z);
  stored_ = Int3{bd_.x + 2, bd_.y + 2, bd_.z + 2};  // one ghost layer on every face
  block_floats_ = stored_.x * stored_.y * stored_.z;
  grid_ = Int3{(dims_.x + bd_.x - 1) / bd_.x, (dims_.y + bd_.y - 1) / bd_.y, (dims_.z + bd_.z - 1) / bd_.z};
  n_blocks_ = grid_.x * grid_.y * grid_.z;

  const int threads = std::max(1, opts.io_threads);
  const uint64_t block_bytes = uint64_t(block_floats_) * sizeof(float);
  const uint64_t fixed = uint64_t(threads) * file_->scratch_bytes(stored_);
  const int64_t fit = opts.memory_budget > fixed ? int64_t((opts.memory_budget - fixed) / block_bytes) : 0;
  if (opts.blocks > 0) {
    R_ = opts.blocks;
    S_ = opts.refresh > 0 ? opts.refresh : default_refresh(R_);
  } else {
    // The paper's R = 65,536 scaled down to the budget, and never more blocks than the volume has
    // (a small volume would be trained in core anyway); S = default_refresh(R) of the rest.
    if (opts.refresh > 0) {
      S_ = opts.refresh;
      R_ = std::min<int64_t>({65536, fit - S_, n_blocks_});
    } else {
      // R : S = 4 : 1 of the blocks that fit, or all but the capped S once S reaches the cap.
      const int64_t four_fifths = fit * 4 / 5;
      const int64_t r = four_fifths / 4 > kMaxDefaultRefresh ? fit - kMaxDefaultRefresh : four_fifths;
      R_ = std::min<int64_t>({65536, r, n_blocks_});
      S_ = default_refresh(R_);
    }
  }
  if (R_ < 1 || R_ + S_ > fit)
    fail("the out-of-core buffer does not fit the memory budget of {:.1f} KiB: {} blocks of {}x{}x{} voxels "
         "(+{} being loaded) need {:.1f} KiB; raise --memory-budget or lower --blocks/--refresh/--block-dims",
         double(opts.memory_budget) / 1024, std::max<int64_t>(R_, 1), bd_.x, bd_.y, bd_.z, S_,
         double(uint64_t(std::max<int64_t>(R_, 1) + S_) * block_bytes + fixed) / 1024);
  if (S_ > R_) fail("--refresh ({}) cannot exceed the number of blocks ({})", S_, R_);
  if (R_ + S_ > INT32_MAX) fail("too many blocks ({})", R_ + S_);

  storage_.resize(size_t((R_ + S_) * block_floats_));
  storage_origin_.resize(size_t(R_ + S_));
  slot_storage_.resize(size_t(R_));
  spare_.resize(size_t(S_));
  for (int64_t s = 0; s < S_; ++s) spare_[size_t(s)] = int32_t(R_ + s);

  scratch_.assign(size_t(threads), std::vector<unsigned char>(file_->scratch_bytes(stored_)));
  for (int t = 0; t < threads; ++t) readers_.emplace_back([this, t] { reader_loop(t); });

  // A failed fill (an unreadable block, NaN under NonFinitePolicy::Error) must still stop the readers: the
  // destructor does not run for an object whose constructor throws.
  const auto t0 = std::chrono::steady_clock::now();
  try {
    fill_buffer(opts);
  } catch (...) {
    stop_readers();
    throw;
  }
  fill_seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

void OutOfCoreSampler::fill_buffer(const OutOfCoreOptions& opts) {
  // Initial fill: R random blocks, read in file order (kinder to disks than random order).
  Pcg32 rng(seed_ * 0xA24BAED4963EE407ULL + 0x0C0FFEE, 0xB10C);
  std::vector<Job> fill(static_cast<size_t>(R_));
  for (int64_t s = 0; s < R_; ++s) fill[size_t(s)] = Job{s, int64_t(rng_below(rng, uint32_t(n_blocks_))), int32_t(s)};
  std::vector<Job> ordered = fill;
  std::sort(ordered.begin(), ordered.end(), [](const Job& a, const Job& b) { return a.block < b.block; });
  const size_t batch = size_t(std::max<int64_t>(S_, 256));
  for (size_t b = 0; b < ordered.size(); b += batch) {
    std::vector<Job> part(ordered.begin() + long(b), ordered.begin() + long(std::min(ordered.size(), b + batch)));
    run_jobs(part);
    wait_jobs();
    if (opts.fill_progress) opts.fill_progress(double(std::min(ordered.size(), b + batch)) / double(R_));
  }
  for (const Job& j : fill) slot_storage_[size_t(j.slot)] = j.storage;
}

void OutOfCoreSampler::stop_readers() {
  {
    std::unique_lock<std::mutex> lock(mu_);
    stop_ = true;
  }
  work_cv_.notify_all();
  for (auto& t : readers_)
    if (t.joinable()) t.join();
}

OutOfCoreSampler::~OutOfCoreSampler() { stop_readers(); }

uint64_t OutOfCoreSampler::bytes_held() const {
  uint64_t b = storage_.size() * sizeof(float);
  for (const auto& s : scratch_) b += s.size();
  return b;
}

double OutOfCoreSampler::resident_fraction() const {
  return std::min(1.0, double(R_) * double(bd_.count()) / double(dims_.count()));
}

double OutOfCoreSampler::expected_coverage(int64_t steps) const {
  return 1.0 - std::exp(-(double(R_) + double(S_) * double(steps)) / double(n_blocks_));
}

Int3 OutOfCoreSampler::block_origin(int64_t block) const {
  const int64_t bx = block % grid_.x, by = (block / grid_.x) % grid_.y, bz = block / (grid_.x * grid_.y);
  return Int3{bx * bd_.x, by * bd_.y, bz * bd_.z};
}

void OutOfCoreSampler::reader_loop(int thread) {
  std::unique_lock<std::mutex> lock(mu_);
  for (;;) {
    work_cv_.wait(lock, [&] { return stop_ || (jobs_ && next_job_ < jobs_->size()); });
    if (stop_) return;
    const Job j = (*jobs_)[next_job_++];
    lock.unlock();
    try {
      const Int3 o = block_origin(j.block);
      storage_origin_[size_t(j.storage)] = o;
      read_block(Int3{o.x - 1, o.y - 1, o.z - 1}, storage_.data() + size_t(j.storage) * block_floats_, thread);
    } catch (...) {
      lock.lock();
      if (!error_) error_ = std::current_exception();
      lock.unlock();
    }
    lock.lock();
    if (++jobs_done_ == jobs_->size()) done_cv_.notify_all();
  }
}

void OutOfCoreSampler::read_block(Int3 origin, float* out, int thread) {
  // Ghosts beyond the region's faces repeat its edge voxels, as the in-core lookup on the region's volume does.
  const Box3 region{origin_, Int3{origin_.x + dims_.x, origin_.y + dims_.y, origin_.z + dims_.z}};
  file_->read_box(Int3{origin_.x + origin.x, origin_.y + origin.y, origin_.z + origin.z}, stored_, out,
                  scratch_[size_t(thread)].data(), region);
}

void OutOfCoreSampler::run_jobs(std::vector<Job>& jobs) {
  {
    std::unique_lock<std::mutex> lock(mu_);
    jobs_ = &jobs;
    next_job_ = 0;
    jobs_done_ = 0;
  }
  work_cv_.notify_all();
}

void OutOfCoreSampler::wait_jobs() {
  std::unique_lock<std::mutex> lock(mu_);
  done_cv_.wait(lock, [&] { return jobs_ == nullptr || jobs_done_ == jobs_->size(); });
  blocks_loaded_ += jobs_ ? jobs_->size() : 0;
  jobs_ = nullptr;
  if (error_) {
    std::exception_ptr e = error_;
    error_ = nullptr;
    std::rethrow_exception(e);
  }
}

void OutOfCoreSampler::begin_step(uint64_t step) {
  file_->check_unchanged();
  if (!pending_.empty()) {
    auto t0 = std::chrono::steady_clock::now();
    wait_jobs();
    io_wait_seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    // The loaded storages take over their slots; the storages they replace become the spares.
    for (size_t j = 0; j < pending_.size(); ++j) std::swap(slot_storage_[size_t(pending_[j].slot)], spare_[j]);
  }
  // Choose this step's replacements; they are read while the step trains.
  Pcg32 rng(seed_ * 0x9E3779B97F4A7C15ULL + step * 0xC2B2AE3D27D4EB4FULL + 0x5EED, 0xB10C);
  pending_.resize(size_t(S_));
  for (int64_t j = 0; j < S_; ++j) {
    int64_t slot = rng_below(rng, uint32_t(R_));
    int64_t block = rng_below(rng, uint32_t(n_blocks_));
    pending_[size_t(j)] = Job{slot, block, spare_[size_t(j)]};
  }
  run_jobs(pending_);
}

void OutOfCoreSampler::sample(uint64_t seed, uint64_t step, uint64_t chunk, int n, float* x, float* y, float* z,
                              float* target) const {
  Pcg32 rng = chunk_rng(seed, step, chunk);
  const float fx = float(dims_.x), fy = float(dims_.y), fz = float(dims_.z);
  const int64_t gx = stored_.x, gxy = stored_.x * stored_.y;
  for (int i = 0; i < n; ++i) {
    // Random block of the buffer, random voxel of its interior; voxels outside the volume (blocks
    // on the far faces are partial) are rejected together with their block, so every voxel of the
    // buffer is equally likely.
    int32_t st;
    Int3 o, v;
    do {
      st = slot_storage_[rng_below(rng, uint32_t(R_))];
      o = storage_origin_[size_t(st)];
      v = Int3{o.x + rng_below(rng, uint32_t(bd_.x)), o.y + rng_below(rng, uint32_t(bd_.y)),
               o.z + rng_below(rng, uint32_t(bd_.z))};
    } while (v.x >= dims_.x || v.y >= dims_.y || v.z >= dims_.z);
    // Jitter: uniform inside the voxel's cell, u in [v/N, (v+1)/N).
    x[i] = (float(v.x) + rng.next_float()) / fx;
    y[i] = (float(v.y) + rng.next_float()) / fy;
    z[i] = (float(v.z) + rng.next_float()) / fz;
    const float* b = storage_.data() + size_t(st) * block_floats_;
    const int64_t ox = o.x - 1, oy = o.y - 1, oz = o.z - 1;  // global index of the block's first ghost
    target[i] = cell_centred_trilinear(int32_t(dims_.x), int32_t(dims_.y), int32_t(dims_.z), x[i], y[i], z[i],
                                       [&](int32_t gxi, int32_t gyi, int32_t gzi) {
                                         return b[(gxi - ox) + (gyi - oy) * gx + (gzi - oz) * gxy];
                                       });
  }
}

// ---------------------------------------------------------------------------------------------
namespace {

// A mapped file that shrinks under us raises SIGBUS on the next access to the lost pages; say what
// happened in one line instead of dying with "Bus error".
extern "C" void on_sigbus(int) {
  static const char msg[] =
      "error: the memory-mapped volume file became shorter during training (SIGBUS); the last checkpoint, if "
      "any, is intact\n";
  ssize_t r = ::write(2, msg, sizeof msg - 1);
  (void)r;
  ::_exit(1);
}

}  // namespace

MmapSampler::MmapSampler(std::shared_ptr<const MappedVolume> volume) : vol_(std::move(volume)) {
  struct sigaction sa;
  std::memset(&sa, 0, sizeof sa);
  sa.sa_handler = on_sigbus;
  ::sigaction(SIGBUS, &sa, nullptr);
}

void MmapSampler::begin_step(uint64_t) { vol_->check_unchanged(); }

void MmapSampler::sample(uint64_t seed, uint64_t step, uint64_t chunk, int n, float* x, float* y, float* z,
                         float* target) const {
  uniform_coordinates(seed, step, chunk, n, x, y, z);
  vol_->lookup(x, y, z, n, target);
}

}  // namespace vnr
