// A renderer's copy of the brick cache (render/brick_cache_view.h, BrickCacheCopySource): what the GPU
// renderer keeps in GPU memory (render_cuda/cache_copy.cuh), kept here in host memory with the same
// steps -- the host cache prepares a frame, the copy takes what changed, the frame reads the copy with
// BrickCacheCopyReads (the GPU's code, its atomics as GCC's builtins here), the host cache takes back the
// slot stamps and requests. Checked against independent references: after every frame the copy's page
// tables equal the host cache's entry for entry and every lookup equals the host's bit for bit, while
// the pool evicts; a warm copy renders a grid's image bit for bit; and the slot stamps that come back
// keep the pool from evicting what the frames read (no thrashing under a budget the view exceeds); and
// changes a copy leaves untaken stay bounded and, taken late, still bring it up to date.
#include <gtest/gtest.h>
#include <algorithm>
#include <cmath>
#include <vector>
#include "vnr/core/rng.h"
#include "vnr/fields/fields.h"
#include "vnr/render/inshader.h"
#include "brick_cache_support.h"

using namespace vnr;
using namespace vnr::test;

namespace {

struct NoReads {  // a lookup that records nothing: the reference reads of a test
  void read(int, int64_t, int32_t) const {}
  void ask(int, int64_t) const {}
  void missed() const {}
};

// The copy: cache_copy.cuh's DeviceCacheCopy with host vectors for GPU buffers (the same upkeep,
// update_cache_copy, and the same reads).
class HostCacheCopy final : public Field {
public:
  explicit HostCacheCopy(const CachedField& src) : src_(src) {
    const BrickCacheView& v = src.view();
    pool_.resize(size_t(src.pool_slots()) * size_t(v.brick_floats));
    table_.assign(size_t(v.level_offset(v.levels)), -1);
    asked_.assign(table_.size(), 0);
    slot_read_.assign(size_t(src.pool_slots()), 0);
    requests_.resize(2 * kRequests);
    reads_.slot_read = slot_read_.data();
    reads_.asked = asked_.data();
    reads_.set_levels(v);
    reads_.requests = requests_.data();
    reads_.n_requests = &n_requests_;
    reads_.capacity = kRequests;
    reads_.misses = &misses_;
  }
  Int3 dims() const override { return src_.dims(); }
  const char* kind() const override { return "cache copy"; }
  void query(const float* x, const float* y, const float* z, int64_t n, float* out) const override {
    for (int64_t i = 0; i < n; ++i) out[i] = point(reads_, x[i], y[i], z[i]);
  }
  // Each thread's copy of the lambda holds its own memo, for this frame: the GPU kernels' reads.
  int64_t render_inshader(const InshaderJob& job) const override {
    return run_inshader(job, [this, memo = BrickCacheCopyReads::Memo{&reads_}](float x, float y, float z) {
      return point(memo, x, y, z);
    });
  }
  void begin_frame(const RenderParams& p) const override {
    const int64_t bf = src_.view().brick_floats;
    const BrickCacheView& v = update_cache_copy(
        src_, p, fresh_,
        [&](int32_t s, int32_t n, const float* voxels) { std::copy_n(voxels, n * bf, pool_.data() + s * bf); },
        [&](const std::vector<std::pair<int64_t, int32_t>>& entries) {
          for (const auto& [index, slot] : entries) table_[size_t(index)] = slot;
        });
    fresh_ = false;
    lookup_ = v.over_copy(table_.data(), pool_.data());
    reads_.frame = v.frame;
  }
  template <class Reads>
  float point(const Reads& reads, float x, float y, float z) const {
    bool miss = false;
    const float v = lookup_.sample(reads, x, y, z, &miss);
    return miss ? 0.0f : v;
  }
  void end_frame() const {
    src_.take_reads(slot_read_.data(), requests_.data(), std::min(n_requests_, kRequests), int64_t(misses_));
    n_requests_ = 0;
    misses_ = 0;
  }
  // The copy's lookup, recording nothing.
  float reference_point(float x, float y, float z) const {
    bool miss = false;
    const float v = lookup_.sample(NoReads{}, x, y, z, &miss);
    return miss ? -1.0f : v;
  }
  const std::vector<int32_t>& table() const { return table_; }

private:
  static constexpr uint32_t kRequests = 64;  // few: requests past it wait for later frames
  const CachedField& src_;
  mutable bool fresh_ = true;
  mutable std::vector<float> pool_;
  mutable std::vector<int32_t> table_, requests_;
  mutable std::vector<uint32_t> asked_, slot_read_;
  mutable uint32_t n_requests_ = 0;
  mutable unsigned long long misses_ = 0;
  mutable BrickCacheCopyReads reads_;
  mutable BrickCacheLookup lookup_;
};

// The host cache's own lookup (coarser misses), recording nothing.
float host_point(const CachedField& cache, float x, float y, float z) {
  bool miss = false;
  const BrickCacheLookup& c = cache.view();
  const float v = c.sample(NoReads{}, x, y, z, &miss);
  return miss ? -1.0f : v;
}

BrickCacheSettings coarser(uint64_t budget) {
  BrickCacheSettings s;
  s.brick = 8;
  s.budget_bytes = budget;
  s.misses = CacheMisses::Coarser;
  s.decode_seconds = 1e-9;  // one brick a frame: frames read a partly warm copy
  return s;
}

}  // namespace

TEST(BrickCacheCopy, FollowsTheHostCacheEntryForEntryWhileThePoolEvicts) {
  Volume vol = synth(Int3{64, 56, 48});
  GridField grid(view_of(vol));
  const uint64_t brick_bytes = 9 * 9 * 9 * sizeof(float);
  CachedField cache(grid, grid_decode(vol), vol.dims, coarser(24 * brick_bytes));
  HostCacheCopy copy(cache);
  RampScene scene(vol, 48, 40);
  Pcg32 rng(9);
  Image img;
  for (int frame = 0; frame < 40; ++frame) {  // the camera circles in from afar: levels 3 to 0, evicting
    const float a = 0.3f * float(frame), d = 400.0f - 9.0f * float(frame);
    const Vec3f centre = box_of(vol) * 0.5f;
    const Camera cam{centre + Vec3f{d * std::cos(a), 0.4f * d, d * std::sin(a)}, centre, Vec3f{0, 1, 0}, 30};
    CpuRenderer(copy, box_of(vol), scene.mc, scene.tf, cam, scene.o).render_frame(uint32_t(frame), img);
    copy.end_frame();
    const BrickCacheView& v = cache.view();
    for (int l = 0; l < v.levels; ++l)
      for (int64_t b = 0; b < v.level_offset(l + 1) - v.level_offset(l); ++b)
        ASSERT_EQ(copy.table()[size_t(v.level_offset(l) + b)], v.level[l].slot[b]) << "frame " << frame << " level " << l;
    for (int i = 0; i < 2000; ++i) {
      const float x = rng.next_float(), y = rng.next_float(), z = rng.next_float();
      ASSERT_EQ(copy.reference_point(x, y, z), host_point(cache, x, y, z)) << "frame " << frame;
    }
  }
  const BrickCacheStats st = cache.stats();
  EXPECT_GT(st.evicted, 0) << "the budget of 24 bricks made the pool evict";
  EXPECT_GT(st.levels, 3);
  EXPECT_LE(st.resident, 24);
}

// A copy no longer drawn (the host cache drawn on the CPU from then on): what the cache records for it
// stays bounded by its pool, and taken late it still brings the copy up to date entry for entry.
TEST(BrickCacheCopy, ChangesLeftUntakenStayBoundedAndBringTheCopyUpToDate) {
  Volume vol = synth(Int3{64, 56, 48});
  GridField grid(view_of(vol));
  BrickCacheSettings s = coarser(24 * 9 * 9 * 9 * sizeof(float));
  s.decode_seconds = 100;  // every brick asked for: many changes a frame
  CachedField cache(grid, grid_decode(vol), vol.dims, s);
  HostCacheCopy copy(cache);
  RampScene scene(vol, 48, 40);
  Image img;
  const Vec3f centre = box_of(vol) * 0.5f;
  auto camera = [&](int frame) {
    const float a = 0.3f * float(frame), d = 400.0f - 9.0f * float(frame % 40);
    return Camera{centre + Vec3f{d * std::cos(a), 0.4f * d, d * std::sin(a)}, centre, Vec3f{0, 1, 0}, 30};
  };
  CpuRenderer(copy, box_of(vol), scene.mc, scene.tf, camera(0), scene.o).render_frame(0, img);
  copy.end_frame();
  int64_t most = 0;
  for (int frame = 1; frame < 1000; ++frame) {  // the host cache alone, evicting
    CpuRenderer(cache, box_of(vol), scene.mc, scene.tf, camera(frame), scene.o).render_frame(uint32_t(frame), img);
    most = std::max(most, cache.changes_pending());
  }
  const BrickCacheStats st = cache.stats();
  std::printf("decoded %lld evicted %lld, most pending %lld\n", (long long)st.decoded, (long long)st.evicted,
              (long long)most);
  EXPECT_GT(st.decoded, 1000) << "many more changes than the bound";
  const int64_t bricks = cache.view().level_offset(cache.view().levels);
  EXPECT_LE(most, 2 * (2 * 24 + 64) + std::max<int64_t>(4 * 24 + 64, 2 * bricks)) << "slots and entries, compacted";
  CpuRenderer(copy, box_of(vol), scene.mc, scene.tf, camera(1000), scene.o).render_frame(0, img);
  const BrickCacheView& v = cache.view();
  for (int64_t i = 0; i < bricks; ++i) {
    int l = 0;
    while (v.level_offset(l + 1) <= i) ++l;
    ASSERT_EQ(copy.table()[size_t(i)], v.level[l].slot[i - v.level_offset(l)]) << "entry " << i;
  }
  Pcg32 rng(5);
  for (int i = 0; i < 2000; ++i) {
    const float x = rng.next_float(), y = rng.next_float(), z = rng.next_float();
    ASSERT_EQ(copy.reference_point(x, y, z), host_point(cache, x, y, z));
  }
}

// Level 0 everywhere over a grid source: once the copy has every brick the view asked for, its images
// are the grid's, bit for bit (the same voxels, the same cell-centred trilinear arithmetic).
TEST(BrickCacheCopy, AWarmCopyRendersTheGridsImageBitForBit) {
  Volume vol = synth(Int3{40, 36, 29});  // partial bricks on every axis
  GridField grid(view_of(vol));
  BrickCacheSettings s = level0(8);
  s.misses = CacheMisses::Coarser;
  s.decode_seconds = 100;  // every brick asked for, before the next frame
  CachedField cache(grid, grid_decode(vol), vol.dims, s);
  HostCacheCopy copy(cache);
  RampScene scene(vol, 40, 32);
  const Camera cam = orbit_camera(box_of(vol), 35, 25, 30);
  const Image ref = CpuRenderer(grid, box_of(vol), scene.mc, scene.tf, cam, scene.o).render(1);
  Image img;
  int frame = 0;
  for (; frame < 10; ++frame) {  // more than the request capacity of 64 a frame: several frames
    CpuRenderer(copy, box_of(vol), scene.mc, scene.tf, cam, scene.o).render_frame(0, img);
    copy.end_frame();
    if (same_image(img, ref)) break;
  }
  EXPECT_TRUE(same_image(img, ref));
  EXPECT_GT(frame, 1) << "the first frames read coarser levels";
  EXPECT_EQ(cache.stats().resident, 5 * 5 * 4 + 1) << "level 0's bricks and the root";
}

// The slot stamps a frame over the copy hands back are the least-recently-used order of the host cache:
// under a budget smaller than what the view reads, the bricks the frames read stay (the rest of the view
// waits at coarser levels) instead of evicting one another every frame.
TEST(BrickCacheCopy, TheFramesReadsKeepThePoolFromThrashing) {
  Volume vol = synth(Int3{32, 32, 32});  // 4 x 4 x 4 bricks of 8
  GridField grid(view_of(vol));
  BrickCacheSettings s = level0(8, 20 * 9 * 9 * 9 * sizeof(float));  // the view reads all 64
  s.misses = CacheMisses::Coarser;
  s.decode_seconds = 100;
  CachedField cache(grid, grid_decode(vol), vol.dims, s);
  HostCacheCopy copy(cache);
  RampScene scene(vol, 32, 32);
  const Camera cam = orbit_camera(box_of(vol), 35, 25, 30);
  Image img;
  int64_t decoded_after_fill = -1;
  for (int frame = 0; frame < 12; ++frame) {
    CpuRenderer(copy, box_of(vol), scene.mc, scene.tf, cam, scene.o).render_frame(0, img);
    copy.end_frame();
    if (frame == 5) decoded_after_fill = cache.stats().decoded;
  }
  const BrickCacheStats st = cache.stats();
  EXPECT_EQ(st.decoded, decoded_after_fill) << "no brick decoded again after the pool filled";
  EXPECT_EQ(st.evicted, 0) << "every resident brick is read by every frame";
  EXPECT_EQ(st.resident, 20);
}
