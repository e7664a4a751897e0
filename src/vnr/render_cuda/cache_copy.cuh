#pragma once
// The brick cache in GPU memory (CUDA-only header of gpu_renderer.cu): a copy of a host cache's pool and
// page tables (render/brick_cache_view.h, BrickCacheCopySource) that the in-shader kernels read with the
// same lookup as the host's frames, per sample at its own level of detail. Before a frame the host cache
// decodes what earlier frames asked for and the copy takes what changed; after it, the frame's slot
// stamps and requests go back to the host cache, whose budget, priorities and eviction decide.
#include <algorithm>
#include <cuda_runtime.h>
#include <vector>
#include "vnr/cuda/common.h"
#include "vnr/render/brick_cache_view.h"
#include "vnr/render/integrators.h"

namespace vnr::gpu_render {

// The copy as a lane evaluator: every lane looks up its own point. A sample no level answers (only
// before the root brick is in) reads 0: the copy's misses read the nearest decoded coarser level.
struct CacheWarpField {
  const BrickCacheLookup* lookup;  // in GPU memory (a kernel parameter of this size would be copied per thread)
  const BrickCacheCopyReads* reads;
  struct Eval {  // one thread's, for one kernel of one frame
    const BrickCacheLookup* c;
    BrickCacheCopyReads::Memo r;
    __device__ bool any(bool active) const { return __any_sync(cuda::kFullWarp, active); }
    __device__ float operator()(bool active, float x, float y, float z) const {
      if (!active) return 0.0f;
      bool miss = false;
      const float v = c->sample(r, x, y, z, &miss);
      return miss ? 0.0f : v;
    }
  };
  __device__ Eval bind(unsigned char*) const { return Eval{lookup, BrickCacheCopyReads::Memo{reads}}; }
};

__global__ void set_cache_entries(const int64_t* __restrict__ index, const int32_t* __restrict__ slot, int64_t n,
                                  int32_t* __restrict__ table) {
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i < n) table[index[i]] = slot[i];
}

class DeviceCacheCopy {
public:
  static constexpr uint32_t kRequests = 1 << 16;  // bricks a frame asks for at most (the rest: next frames)

  explicit DeviceCacheCopy(const BrickCacheCopySource& src) : src_(src) {
    const BrickCacheView& v = src.view();
    if (!v.coarser)  // the copy's misses read coarser levels, and the host decodes the root first only then
      cuda::cuda_fail_message("the GPU draws only a brick cache whose misses read coarser levels "
                              "(CacheMisses::Coarser, as cache_settings_for gives)");
    const size_t slots = size_t(src.pool_slots()), pool_floats = slots * size_t(v.brick_floats);
    size_t free_b = 0, total_b = 0;
    VNR_CUDA_CHECK(cudaMemGetInfo(&free_b, &total_b));
    if (pool_floats * sizeof(float) > free_b / 2)
      cuda::cuda_fail_message("the brick cache's pool (" + std::to_string((pool_floats * sizeof(float)) >> 20) +
                              " MiB) is more than half the GPU's free memory (" + std::to_string(free_b >> 20) +
                              " MiB): give a smaller --cache-budget");
    pool_.resize(pool_floats);
    const int64_t bricks = v.level_offset(v.levels);
    table_.resize(size_t(bricks));
    asked_.resize(size_t(bricks));
    slot_read_.resize(slots);
    requests_.resize(2 * size_t(kRequests));
    counts_.resize(1);
    misses_.resize(1);
    VNR_CUDA_CHECK(cudaMemset(table_.data(), 0xff, table_.size() * sizeof(int32_t)));  // -1: not decoded
    VNR_CUDA_CHECK(cudaMemset(asked_.data(), 0, asked_.size() * sizeof(uint32_t)));
    VNR_CUDA_CHECK(cudaMemset(slot_read_.data(), 0, slot_read_.size() * sizeof(uint32_t)));
    host_slot_read_.resize(slots);
    host_requests_.resize(2 * size_t(kRequests));
    lookup_.resize(1);
    reads_.resize(1);
    reads_h_.slot_read = slot_read_.data();
    reads_h_.asked = asked_.data();
    reads_h_.set_levels(v);
    reads_h_.requests = requests_.data();
    reads_h_.n_requests = counts_.data();
    reads_h_.capacity = kRequests;
    reads_h_.misses = misses_.data();
  }

  // The host cache prepares frame p (decodes what was asked for), and the copy takes what changed.
  void begin_frame(const RenderParams& p) {
    const size_t bf = size_t(src_.view().brick_floats);
    const auto copy_slots = [&](int32_t s, int32_t n, const float* voxels) {
      pool_.upload(voxels, size_t(n) * bf, size_t(s) * bf);
    };
    const auto set_entries = [&](const std::vector<std::pair<int64_t, int32_t>>& entries) {
      const size_t n = entries.size();
      std::vector<int64_t> index(n);
      std::vector<int32_t> slot(n);
      for (size_t i = 0; i < n; ++i) index[i] = entries[i].first, slot[i] = entries[i].second;
      if (entry_index_.size() < n) {  // grown geometrically: a reallocation synchronises the device
        const size_t capacity = std::max(n, 2 * entry_index_.size());
        entry_index_.resize(capacity), entry_slot_.resize(capacity);
      }
      entry_index_.upload(index.data(), n);
      entry_slot_.upload(slot.data(), n);
      set_cache_entries<<<cuda::blocks_for(int64_t(n), 256), 256>>>(entry_index_.data(), entry_slot_.data(),
                                                                    int64_t(n), table_.data());
      VNR_CUDA_LAUNCHED();
    };
    const BrickCacheView& v = update_cache_copy(src_, p, fresh_, copy_slots, set_entries);
    fresh_ = false;
    const BrickCacheLookup c = v.over_copy(table_.data(), pool_.data());  // the host's levels and view
    reads_h_.frame = v.frame;
    // The frame's counters start at zero (here, not after the last frame: that one may have thrown).
    VNR_CUDA_CHECK(cudaMemset(counts_.data(), 0, sizeof(uint32_t)));
    VNR_CUDA_CHECK(cudaMemset(misses_.data(), 0, sizeof(unsigned long long)));
    lookup_.upload(&c, 1);
    reads_.upload(&reads_h_, 1);  // synchronous (legacy stream): done before the frame's kernels
    VNR_CUDA_CHECK(cudaDeviceSynchronize());
  }

  CacheWarpField field() const { return CacheWarpField{lookup_.data(), reads_.data()}; }

  // After the frame on `stream`: its slot stamps and requests go to the host cache.
  void end_frame(cudaStream_t stream) {
    VNR_CUDA_CHECK(cudaStreamSynchronize(stream));
    uint32_t n = 0;
    unsigned long long misses = 0;
    counts_.download(&n, 1);
    misses_.download(&misses, 1);
    n = std::min(n, kRequests);
    if (n) requests_.download(host_requests_.data(), 2 * size_t(n));
    slot_read_.download(host_slot_read_.data(), host_slot_read_.size());
    src_.take_reads(host_slot_read_.data(), host_requests_.data(), int64_t(n), int64_t(misses));
  }

private:
  const BrickCacheCopySource& src_;
  bool fresh_ = true;
  cuda::DeviceBuffer<float> pool_;
  cuda::DeviceBuffer<int32_t> table_, requests_, entry_slot_;
  cuda::DeviceBuffer<uint32_t> asked_, slot_read_, counts_;
  cuda::DeviceBuffer<unsigned long long> misses_;
  cuda::DeviceBuffer<int64_t> entry_index_;
  cuda::DeviceBuffer<BrickCacheLookup> lookup_;
  cuda::DeviceBuffer<BrickCacheCopyReads> reads_;
  BrickCacheCopyReads reads_h_;
  std::vector<uint32_t> host_slot_read_;
  std::vector<int32_t> host_requests_;
};

}  // namespace vnr::gpu_render
