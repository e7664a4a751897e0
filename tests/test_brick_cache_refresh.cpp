// Refreshing the brick cache (fields/brick_cache.h) when its model changes, as training in the loop
// changes it: against the grids of the old and the new model, stale bricks are read until refreshed, a
// frame refreshes within its budget exactly the bricks it reports, and refreshing sweeps every brick of
// the view while the model keeps changing (none is left at the first model's values).
#include <gtest/gtest.h>
#include <set>
#include <vector>
#include "vnr/core/rng.h"
#include "vnr/fields/brick_cache.h"
#include "vnr/render/renderer.h"
#include "test_support.h"
#include "brick_cache_support.h"

using namespace vnr;
using namespace vnr::test;

namespace {

// A cache of model a whose model then changes to b (1 - a): what training in the loop does to it.
struct ChangingModel : ::testing::Test {
  Volume a = synth(Int3{32, 32, 32}), b = inverted(a);
  GridField field_a{view_of(a)}, field_b{view_of(b)};
  const Volume* current = &a;
  CachedField cache{field_a,
                    [this](Int3 dims, const int64_t* index, int64_t n, float* out) { grid_decode(*current)(dims, index, n, out); },
                    a.dims, settings()};
  const RenderParams p = params_for(orbit_camera(box_of(a), 0, 0, 30), a.dims, 64, 64);

  static Volume inverted(Volume v) {
    for (float& x : v.data) x = 1 - x;
    return v;
  }
  static BrickCacheSettings settings() {
    BrickCacheSettings s = level0(8);
    s.decode_seconds = 100;
    return s;
  }
  void change() {
    current = &b;
    cache.replace_source(field_b, true);
  }
};

TEST_F(ChangingModel, AChangedModelRefreshesItsBricksWithinTheFrameBudget) {
  std::vector<float> x, y, z;
  Pcg32 rng(3);
  for (int i = 0; i < 4000; ++i) x.push_back(rng.next_float()), y.push_back(rng.next_float()), z.push_back(rng.next_float());
  std::vector<float> v(x.size());
  cache.begin_frame(p);
  cache.query(x.data(), y.data(), z.data(), int64_t(x.size()), v.data());
  cache.begin_frame(p);  // decodes all 64 bricks
  ASSERT_EQ(cache.stats().resident, 64);
  const uint64_t version = cache.content_version();
  change();
  EXPECT_EQ(cache.stats().stale, 64);
  cache.query(x.data(), y.data(), z.data(), int64_t(x.size()), v.data());
  for (size_t i = 0; i < x.size(); ++i) ASSERT_EQ(v[i], grid_lookup(view_of(a), x[i], y[i], z[i])) << "stale bricks are still read";
  cache.begin_frame(p);  // refreshes every brick the frame read
  EXPECT_EQ(cache.stats().stale, 0);
  EXPECT_GT(cache.content_version(), version);
  cache.query(x.data(), y.data(), z.data(), int64_t(x.size()), v.data());
  for (size_t i = 0; i < x.size(); ++i) ASSERT_EQ(v[i], grid_lookup(view_of(b), x[i], y[i], z[i]));
}

TEST_F(ChangingModel, RefreshChangesExactlyTheRefreshedBricks) {
  // One sample at the centre of each of the 64 bricks.
  std::vector<float> x, y, z;
  for (int k = 0; k < 4; ++k)
    for (int j = 0; j < 4; ++j)
      for (int i = 0; i < 4; ++i) x.push_back((8.0f * i + 4) / 32), y.push_back((8.0f * j + 4) / 32), z.push_back((8.0f * k + 4) / 32);
  std::vector<float> v(64);
  cache.begin_frame(p);
  cache.query(x.data(), y.data(), z.data(), 64, v.data());
  cache.begin_frame(p);
  ASSERT_EQ(cache.stats().resident, 64);
  change();
  cache.set_decode_seconds(1e-9);  // one brick a frame
  for (int frame = 1; frame <= 3; ++frame) {
    cache.query(x.data(), y.data(), z.data(), 64, v.data());
    cache.begin_frame(p);
    EXPECT_EQ(cache.stats().stale, 64 - frame);
    cache.query(x.data(), y.data(), z.data(), 64, v.data());
    int changed = 0;
    for (int i = 0; i < 64; ++i) {
      const float old_value = grid_lookup(view_of(a), x[i], y[i], z[i]), new_value = grid_lookup(view_of(b), x[i], y[i], z[i]);
      ASSERT_TRUE(v[i] == old_value || v[i] == new_value);
      changed += v[i] == new_value;
    }
    EXPECT_EQ(changed, frame) << "exactly the refreshed bricks read the new model";
  }
}

// While a model trains, every resident brick turns stale at every step, and a frame's budget refreshes a
// few: oldest first, each brick of the view is refreshed once every (resident / per frame) frames.
TEST(BrickCache, WhileTheModelKeepsChangingEveryBrickOfTheViewIsRefreshed) {
  const Volume vol = synth(Int3{64, 64, 64});
  GridField field(view_of(vol));
  std::set<int64_t> refreshed;  // bricks by their first voxel and level dims
  bool recording = false;
  BrickCacheSettings s = level0(8);
  s.decode_seconds = 100;
  CachedField cache(field,
                    [&](Int3 dims, const int64_t* index, int64_t n, float* out) {
                      grid_decode(vol)(dims, index, n, out);
                      if (recording) refreshed.insert(index[0] * 4096 + dims.x);
                    },
                    vol.dims, s);
  RampScene scene(vol, 96, 96);
  const Camera cam = orbit_camera(box_of(vol), 40, 25, 30);
  CpuRenderer renderer(cache, box_of(vol), scene.mc, scene.tf, cam, scene.o);
  Image img;
  for (int f = 0; f < 4; ++f) renderer.render_frame(0, img);
  const int64_t resident = cache.stats().resident;
  ASSERT_GT(resident, 100);
  cache.set_decode_seconds(0);  // one brick a frame
  recording = true;
  for (int64_t f = 0; f < resident; ++f) {
    cache.replace_source(field, true);  // a training step
    renderer.render_frame(0, img);
  }
  EXPECT_EQ(int64_t(refreshed.size()), resident) << "one refresh a frame for as many frames as bricks";
  EXPECT_EQ(cache.stats().resident, resident);
}

}  // namespace
