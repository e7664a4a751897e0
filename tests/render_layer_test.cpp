// The render layer on its own: this executable links vnr_render (and what it depends on: core) and
// nothing else, so it fails to link if render ever needs volume, nn, train or the fields layer.
// Through a field view defined here, it checks that the CPU renderer's two strategies drive the one
// shared per-pixel loop (inshader_loop.h) and per-slot stages (stream_stages.h): with K = 1 both take
// exactly the same field samples and give the same image, bit for bit.
#include <gtest/gtest.h>
#include <atomic>
#include <cstring>
#include "test_support.h"
#include "vnr/grid_view.h"
#include "vnr/core/value_range_grid.h"
#include "vnr/render/field.h"
#include "vnr/render/inshader.h"
#include "vnr/render/macrocell.h"
#include "vnr/render/renderer.h"

namespace vnr {
namespace {

// The grid as a field that counts its evaluations: point evaluations (in-shader) and batched points
// (streaming), each through the per-point lookup.
class CountingGridField final : public Field {
public:
  explicit CountingGridField(GridView g) : g_(g) {}
  Int3 dims() const override { return Int3{g_.nx, g_.ny, g_.nz}; }
  const char* kind() const override { return "grid"; }
  void query(const float* x, const float* y, const float* z, int64_t n, float* out) const override {
    batched_ += n;
    for (int64_t i = 0; i < n; ++i) out[i] = grid_lookup(g_, x[i], y[i], z[i]);
  }
  int64_t render_inshader(const InshaderJob& job) const override {
    struct CountingPointFn {
      const CountingGridField* f;
      float operator()(float x, float y, float z) const {
        f->points_.fetch_add(1, std::memory_order_relaxed);
        return grid_lookup(f->g_, x, y, z);
      }
    };
    return run_inshader(job, CountingPointFn{this});
  }
  int64_t points() const { return points_.load(); }
  int64_t batched() const { return batched_.load(); }

private:
  GridView g_;
  mutable std::atomic<int64_t> points_{0}, batched_{0};
};

struct Frame {
  Image img;
  RenderStats st;
  int64_t counted = 0;  // evaluations the field saw
};

Frame render_with(const Volume& vol, RenderMode mode, RenderStrategy strategy, bool shade, int K) {
  CountingGridField field(view_of(vol));
  TransferFunction tf = tf_preset("ramp");
  MacroCells mc(value_ranges_from_grid(view_of(vol), 8), test::box_of(vol));
  mc.update(tf);
  RenderOptions o;
  o.mode = mode;
  o.strategy = strategy;
  o.shade = shade;
  o.width = 40, o.height = 32;
  o.samples_per_iteration = K;
  o.density_scale = 0.2f;
  o.seed = 7;
  CpuRenderer r(field, test::box_of(vol), mc, tf, orbit_camera(test::box_of(vol), 30, 20, 30), o);
  Frame f;
  f.img = r.render(2, &f.st);
  f.counted = strategy == RenderStrategy::InShader ? field.points() : field.batched();
  return f;
}

TEST(RenderLayer, BothStrategiesTakeTheSameSamplesThroughTheSharedFunctions) {
  // test::blobs, not test::synth: the synthetic fields of volume/synth.cpp are not linked here.
  const Volume vol = test::blobs(Int3{24, 20, 18});
  struct Case {
    RenderMode mode;
    bool shade;
  };
  for (Case c : {Case{RenderMode::RayMarch, false}, Case{RenderMode::RayMarch, true}, Case{RenderMode::Shadow, true},
                 Case{RenderMode::PathTrace, false}}) {
    SCOPED_TRACE(std::string(render_mode_name(c.mode)) + (c.shade ? " shaded" : ""));
    const Frame in = render_with(vol, c.mode, RenderStrategy::InShader, c.shade, 1);
    const Frame st = render_with(vol, c.mode, RenderStrategy::Streaming, c.shade, 1);
    EXPECT_GT(in.counted, 0);
    EXPECT_EQ(in.counted, in.st.field_samples);
    EXPECT_EQ(st.counted, st.st.field_samples);
    EXPECT_EQ(in.counted, st.counted);  // K = 1: no sample is taken past a ray's end
    ASSERT_EQ(in.img.pixels.size(), st.img.pixels.size());
    EXPECT_EQ(0, std::memcmp(in.img.pixels.data(), st.img.pixels.data(), in.img.pixels.size() * sizeof(Vec4f)));
    // K > 1 takes extra samples past ray ends, never a different image
    const Frame st8 = render_with(vol, c.mode, RenderStrategy::Streaming, c.shade, 8);
    EXPECT_GE(st8.counted, st.counted);
    EXPECT_EQ(0, std::memcmp(in.img.pixels.data(), st8.img.pixels.data(), in.img.pixels.size() * sizeof(Vec4f)));
  }
}

}  // namespace
}  // namespace vnr
