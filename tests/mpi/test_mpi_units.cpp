// The MPI layer's pure parts, in one process: visibility order against brute-force ray casting,
// compositing against a per-pixel reference, row bands, and direct send without an MPI session.
#include <gtest/gtest.h>
#include <algorithm>
#include <cmath>
#include <random>
#include <cstdlib>
#include "mpi/comm.h"
#include "mpi/composite.h"
#include "mpi/sort_last.h"
#include "vnr/error.h"

using namespace vnr;
using namespace vnr::mpi;

namespace {
std::vector<Bounds3f> grid_boxes(const std::vector<float>& xs, const std::vector<float>& ys, const std::vector<float>& zs) {
  std::vector<Bounds3f> boxes;
  // Shuffled-looking order (z outermost reversed) so the index tie-break alone cannot pass the test.
  for (size_t k = zs.size() - 1; k-- > 0;)
    for (size_t j = 0; j + 1 < ys.size(); ++j)
      for (size_t i = 0; i + 1 < xs.size(); ++i)
        boxes.push_back({{xs[i], ys[j], zs[k]}, {xs[i + 1], ys[j + 1], zs[k + 1]}});
  return boxes;
}

// Ray-box entry distance (slab method); false when the ray misses.
bool entry(const Bounds3f& b, Vec3f o, Vec3f d, float* t_in) {
  float t0 = 0, t1 = 1e30f;
  const float os[3] = {o.x, o.y, o.z}, ds[3] = {d.x, d.y, d.z}, lo[3] = {b.lo.x, b.lo.y, b.lo.z},
              hi[3] = {b.hi.x, b.hi.y, b.hi.z};
  for (int a = 0; a < 3; ++a) {
    float ta = (lo[a] - os[a]) / ds[a], tb = (hi[a] - os[a]) / ds[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta), t1 = std::min(t1, tb);
  }
  *t_in = t0;
  return t1 - t0 > 1e-4f;  // a real crossing, not a graze of an edge
}
}  // namespace

TEST(MpiComposite, VisibilityOrderAgreesWithRaysFromAnyEye) {
  // Uneven brick sizes, as a plan with a remainder brick makes.
  const std::vector<Bounds3f> boxes = grid_boxes({0, 3, 5, 9}, {0, 4, 6}, {0, 2, 5, 6});
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-8, 16), dir(-1, 1);
  int checked_pairs = 0;
  for (int e = 0; e < 40; ++e) {
    const Vec3f eye{u(rng), u(rng), u(rng)};
    const std::vector<int> order = visibility_order(boxes, eye);
    std::vector<int> position(boxes.size());
    for (size_t i = 0; i < order.size(); ++i) position[size_t(order[i])] = int(i);
    for (int r = 0; r < 400; ++r) {
      const Vec3f d{dir(rng), dir(rng), dir(rng)};
      std::vector<std::pair<float, int>> hits;
      for (size_t b = 0; b < boxes.size(); ++b) {
        float t;
        if (entry(boxes[b], eye, d, &t)) hits.push_back({t, int(b)});
      }
      std::sort(hits.begin(), hits.end());
      for (size_t i = 1; i < hits.size(); ++i) {
        if (hits[i].first - hits[i - 1].first < 1e-4f) continue;  // entered at one point: either order is right
        EXPECT_LT(position[size_t(hits[i - 1].second)], position[size_t(hits[i].second)]) << "eye " << e << " ray " << r;
        ++checked_pairs;
      }
    }
  }
  EXPECT_GT(checked_pairs, 1000);
}

TEST(MpiComposite, FrontToBackOverMatchesTheClosedForm) {
  // Two layers: front (premultiplied) c1, a1 over c2, a2 -> c1 + (1 - a1) c2, a1 + (1 - a1) a2.
  std::vector<Image> imgs(2, Image(1, 1));
  imgs[0].pixels[0] = {0.2f, 0.1f, 0.0f, 0.25f};
  imgs[1].pixels[0] = {0.3f, 0.6f, 0.9f, 0.5f};
  Image out = composite_in_order(imgs, {0, 1});
  EXPECT_FLOAT_EQ(out.pixels[0].x, 0.2f + 0.75f * 0.3f);
  EXPECT_FLOAT_EQ(out.pixels[0].y, 0.1f + 0.75f * 0.6f);
  EXPECT_FLOAT_EQ(out.pixels[0].w, 0.25f + 0.75f * 0.5f);
  Image back = composite_in_order(imgs, {1, 0});
  EXPECT_FLOAT_EQ(back.pixels[0].z, 0.9f + 0.5f * 0.0f);
  put_over_background(out, {1, 1, 1});
  EXPECT_FLOAT_EQ(out.pixels[0].x, 0.2f + 0.75f * 0.3f + (1 - (0.25f + 0.75f * 0.5f)));
  EXPECT_EQ(out.pixels[0].w, 1.0f);
}

TEST(MpiComposite, RowBandsTileTheImage) {
  for (int h : {0, 1, 7, 768})
    for (int n : {1, 2, 3, 4, 64}) {
      int next = 0;
      for (int r = 0; r < n; ++r) {
        RowBand b = row_band(h, r, n);
        EXPECT_EQ(b.y0, next);
        EXPECT_GE(b.rows(), h / n);
        EXPECT_LE(b.rows(), h / n + 1);
        next = b.y1;
      }
      EXPECT_EQ(next, h);
    }
  EXPECT_THROW(row_band(10, 2, 2), Error);
}

TEST(MpiComposite, DirectSendInOneProcessIsTheReference) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0, 1);
  std::vector<Image> imgs(5, Image(9, 6));
  for (Image& img : imgs)
    for (Vec4f& p : img.pixels) {
      const float a = u(rng);
      p = {a * u(rng), a * u(rng), a * u(rng), a};
    }
  const std::vector<int> order = {3, 0, 4, 1, 2};
  std::vector<BrickImage> mine;
  for (int b = 0; b < 5; ++b) mine.push_back({b, &imgs[size_t(b)]});
  Image got = composite_direct_send(mine, std::vector<int>(5, 0), order, 9, 6);
  Image want = composite_in_order(imgs, order);
  for (size_t i = 0; i < want.pixels.size(); ++i) {
    EXPECT_EQ(got.pixels[i].x, want.pixels[i].x);
    EXPECT_EQ(got.pixels[i].w, want.pixels[i].w);
  }
  // A brick image of the wrong size is one clear error.
  Image small(3, 3);
  EXPECT_THROW(composite_direct_send({{0, &small}}, {0}, {0}, 9, 6), Error);
}

// pvpython (ParaView's Python) initialises MPI as a singleton and passes PMIX_RANK to the processes it
// starts; a `vnr` started from it must stay one process (train -o x.vnr writes a file, not bricks).
TEST(MpiLaunch, AnOpenMpiSingletonParentIsNotALaunch) {
  for (const char* v : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK", "OMPI_MCA_ess"}) unsetenv(v);
  EXPECT_FALSE(vnr::mpi::launched_by_mpi());
  setenv("PMIX_RANK", "0", 1);
  EXPECT_TRUE(vnr::mpi::launched_by_mpi());  // srun with PMIx
  setenv("OMPI_MCA_ess", "singleton", 1);
  EXPECT_FALSE(vnr::mpi::launched_by_mpi());
  setenv("OMPI_COMM_WORLD_SIZE", "2", 1);
  EXPECT_TRUE(vnr::mpi::launched_by_mpi());  // mpirun
  for (const char* v : {"OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "OMPI_MCA_ess"}) unsetenv(v);
}
