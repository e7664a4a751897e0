// Multi-brick models (train/bricks.h, docs/MODEL_FORMAT.md "Multi-brick models"): the plan and its
// assignment checked by brute force, the blend against closed forms, seeds independent of the order
// bricks are trained in, --resume, quality against a single model of the same size (faces as accurate
// as the interior, no seams), and every front end opening the directory like one model.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numeric>
#include "bricks_test_support.h"
#include "test_support.h"
#include "vnr/bricks.h"
#include "vnr/metrics.h"
#include "vnr/fields/bricked_field.h"
#include "vnr/train/bricks.h"
#include "vnr/train/evaluate.h"
#include "vnr/train/model_form.h"
#include "vnr/viewer.h"
#include "vnr/volume/raw_access.h"

namespace vnr {
namespace {

using test::TmpDir;

// ---- plan, assignment, seeds ---------------------------------------------------------------------

TEST(BrickPlan, OwnedBoxesTileTheVolumeAndTrainedBoxesAddTheClampedGhost) {
  const Int3 dims{37, 20, 9};
  const BrickPlan p = plan_bricks(dims, Int3{3, 2, 1}, 2, 7);
  ASSERT_EQ(p.bricks.size(), 6u);
  std::vector<int> owner(dims.count(), 0);
  for (const BrickSpec& b : p.bricks) {
    EXPECT_EQ(b.index, int(b.coord.x + 3 * (b.coord.y + 2 * b.coord.z)));
    for (int64_t z = b.owned.lo.z; z < b.owned.hi.z; ++z)
      for (int64_t y = b.owned.lo.y; y < b.owned.hi.y; ++y)
        for (int64_t x = b.owned.lo.x; x < b.owned.hi.x; ++x) ++owner[size_t(x + dims.x * (y + dims.y * z))];
    for (int a = 0; a < 3; ++a) {
      EXPECT_EQ(b.trained.lo[a], std::max<int64_t>(0, b.owned.lo[a] - 2));
      EXPECT_EQ(b.trained.hi[a], std::min<int64_t>(dims[a], b.owned.hi[a] + 2));
      EXPECT_GE(b.owned.size()[a], dims[a] / p.grid[a]);  // as even as integers allow
      EXPECT_LE(b.owned.size()[a], dims[a] / p.grid[a] + 1);
    }
  }
  for (int c : owner) ASSERT_EQ(c, 1);  // every voxel owned exactly once
  const BrickPlan again = plan_bricks(dims, Int3{3, 2, 1}, 2, 7);
  for (size_t i = 0; i < p.bricks.size(); ++i) {
    EXPECT_EQ(again.bricks[i].trained, p.bricks[i].trained);
    EXPECT_EQ(again.bricks[i].seed, p.bricks[i].seed);
  }
}

TEST(BrickPlan, AutoSplitsLongestAxesAndBadGridsFailClearly) {
  const BrickPlan p = plan_bricks(Int3{512, 300, 100}, Int3{0, 0, 0}, 4, 1);
  for (const BrickSpec& b : p.bricks) EXPECT_LE(b.owned.voxels(), auto_brick_voxels);
  EXPECT_EQ(p.grid.z, 1);  // the short axis is never split while longer ones can be
  EXPECT_EQ(plan_bricks(Int3{64, 64, 64}, Int3{0, 0, 0}, 4, 1).bricks.size(), 1u);
  const std::string too_many = test::error_of([] { plan_bricks(Int3{10, 10, 10}, Int3{4, 1, 1}, 4, 1); });
  EXPECT_HAS(too_many, "at most 2");
  EXPECT_HAS(test::error_of([] { parse_brick_grid("2,2"); }), "BX,BY,BZ");
  EXPECT_HAS(test::error_of([] { parse_brick_grid("2,0,1"); }), "BX,BY,BZ");
  EXPECT_EQ(parse_brick_grid("3,1,2"), (Int3{3, 1, 2}));
}

TEST(BrickPlan, AssignmentCoversEveryBrickOnceAndBalancesVoxels) {
  const BrickPlan p = plan_bricks(Int3{70, 50, 30}, Int3{5, 3, 2}, 3, 1);
  uint64_t largest = 0;
  for (const BrickSpec& b : p.bricks) largest = std::max(largest, b.trained.voxels());
  for (int ranks : {1, 2, 3, 4, 7, 40}) {
    const auto a = assign_bricks(p, ranks);
    ASSERT_EQ(int(a.size()), ranks);
    std::vector<int> seen(p.bricks.size(), 0);
    uint64_t lo = UINT64_MAX, hi = 0;
    for (const auto& list : a) {
      uint64_t load = 0;
      for (int b : list) {
        ++seen[size_t(b)];
        load += p.bricks[size_t(b)].trained.voxels();
      }
      EXPECT_TRUE(std::is_sorted(list.begin(), list.end()));
      lo = std::min(lo, load);
      hi = std::max(hi, load);
    }
    for (int s : seen) EXPECT_EQ(s, 1);
    if (ranks <= int(p.bricks.size())) EXPECT_LE(hi - lo, largest) << ranks << " ranks";  // greedy LPT bound
    EXPECT_EQ(assign_bricks(p, ranks), a);
  }
}

// Decoding's share: runs of consecutive bricks, every brick once, each rank within one brick of its
// even share of the voxels.
TEST(BrickPlan, ContiguousSharesCoverEveryBrickOnceInRuns) {
  const BrickPlan p = plan_bricks(Int3{70, 50, 30}, Int3{5, 3, 2}, 3, 1);
  uint64_t total = 0, largest = 0;
  for (const BrickSpec& b : p.bricks) total += b.owned.voxels(), largest = std::max(largest, b.owned.voxels());
  for (int ranks : {1, 2, 3, 4, 7, 40}) {
    std::vector<int> all;
    for (int r = 0; r < ranks; ++r) {
      const std::vector<int> mine = contiguous_bricks(p, r, ranks);
      uint64_t voxels = 0;
      for (size_t k = 0; k < mine.size(); ++k) {
        if (k > 0) EXPECT_EQ(mine[k], mine[k - 1] + 1) << "rank " << r << " of " << ranks;
        voxels += p.bricks[size_t(mine[k])].owned.voxels();
      }
      EXPECT_LE(std::fabs(double(voxels) - double(total) / ranks), double(largest)) << "rank " << r << " of " << ranks;
      all.insert(all.end(), mine.begin(), mine.end());
    }
    std::vector<int> want(p.bricks.size());
    std::iota(want.begin(), want.end(), 0);
    EXPECT_EQ(all, want) << ranks << " ranks";
  }
  EXPECT_THROW(contiguous_bricks(p, 3, 3), Error);
}

// The bricks' output regions tile any output grid, each voxel going to the brick whose owned box holds
// its centre (checked in exact rational arithmetic: centre (2i + 1) / (2 out) of the axis).
TEST(BrickPlan, OutputRegionsTileAnyGridByVoxelCentres) {
  const BrickPlan p = plan_bricks(Int3{40, 36, 32}, Int3{3, 2, 4}, 2, 1);
  for (const Int3 out : {Int3{40, 36, 32}, Int3{33, 20, 17}, Int3{80, 72, 64}, Int3{7, 5, 3}, Int3{1, 1, 1}, Int3{123, 37, 31}}) {
    std::vector<int> owner(out.count(), -1);
    for (const BrickSpec& b : p.bricks) {
      const Box3 r = brick_output_region(p, b.index, out);
      for (int64_t z = r.lo.z; z < r.hi.z; ++z)
        for (int64_t y = r.lo.y; y < r.hi.y; ++y)
          for (int64_t x = r.lo.x; x < r.hi.x; ++x) {
            int& o = owner[size_t((z * out.y + y) * out.x + x)];
            EXPECT_EQ(o, -1) << "voxel " << x << "," << y << "," << z << " taken twice";
            o = b.index;
            const Int3 i{x, y, z};
            for (int a = 0; a < 3; ++a) {  // lo <= (2i + 1) dims / (2 out) < hi
              EXPECT_LE(2 * b.owned.lo[a] * out[a], (2 * i[a] + 1) * p.dims[a]);
              EXPECT_LT((2 * i[a] + 1) * p.dims[a], 2 * b.owned.hi[a] * out[a]);
            }
          }
    }
    EXPECT_EQ(std::count(owner.begin(), owner.end(), -1), 0) << out.x << "x" << out.y << "x" << out.z;
  }
}

// At the scale of the paper's DNS (7200 bricks of 256^3) on 1024 ranks, a rank decoding its run of
// bricks loads them and their neighbours; an even split of z-slices would load whole brick layers.
TEST(BrickPlan, ContiguousSharesLoadFarFewerBricksThanSlabsAtScale) {
  const BrickPlan p = plan_bricks(Int3{10240, 7680, 1536}, Int3{40, 30, 6}, 4, 1);
  ASSERT_EQ(p.bricks.size(), 7200u);
  const int ranks = 1024;
  size_t most_by_bricks = 0, least_by_slabs = SIZE_MAX;
  for (int r = 0; r < ranks; r += 61) {
    std::vector<int> need;
    for (int b : contiguous_bricks(p, r, ranks)) {
      Box3 reach = p.bricks[size_t(b)].owned;
      for (int a = 0; a < 3; ++a)
        reach.lo[a] = std::max<int64_t>(0, reach.lo[a] - 1), reach.hi[a] = std::min(p.dims[a], reach.hi[a] + 1);
      for (int n : bricks_touching(p, reach)) need.push_back(n);
    }
    std::sort(need.begin(), need.end());
    need.erase(std::unique(need.begin(), need.end()), need.end());
    most_by_bricks = std::max(most_by_bricks, need.size());
    const int64_t z0 = p.dims.z * r / ranks, z1 = p.dims.z * (r + 1) / ranks;
    least_by_slabs = std::min(least_by_slabs, bricks_touching(p, Box3{{0, 0, z0}, {p.dims.x, p.dims.y, z1}}).size());
  }
  EXPECT_LE(most_by_bricks, 100u);
  EXPECT_GE(least_by_slabs, 1200u);
}

TEST(BrickPlan, SeedsDependOnSeedAndBrickOnly) {
  std::vector<uint32_t> seeds;
  for (int i = 0; i < 64; ++i) seeds.push_back(brick_seed(1337, i));
  std::sort(seeds.begin(), seeds.end());
  EXPECT_EQ(std::unique(seeds.begin(), seeds.end()), seeds.end());
  EXPECT_EQ(brick_seed(1337, 5), brick_seed(1337, 5));
  EXPECT_NE(brick_seed(1337, 5), brick_seed(1338, 5));
}

// ---- the blend ------------------------------------------------------------------------------------

TEST(BrickBlend, ReproducesAnyFieldTheBricksAgreeOnAndIsContinuousAcrossFaces) {
  const BrickPlan p = plan_bricks(Int3{30, 24, 16}, Int3{3, 2, 2}, 3, 1);
  const BrickLayout l = layout_of(p);
  auto f = [](float x, float y, float z) { return 0.3f + 0.5f * x - 0.2f * y * y + 0.1f * z; };
  Pcg32 rng(3);
  for (int i = 0; i < 2000; ++i) {
    const float u[3] = {rng.next_float(), rng.next_float(), rng.next_float()};
    // Bricks that all know f exactly (in their local coordinates): the blend must give f.
    const float v = l.blend_point(u[0], u[1], u[2], [&](int b, float lx, float ly, float lz) {
      const Box3& t = l.trained[size_t(b)];
      return f((t.lo.x + lx * float(t.size().x)) / 30.f, (t.lo.y + ly * float(t.size().y)) / 24.f,
               (t.lo.z + lz * float(t.size().z)) / 16.f);
    });
    ASSERT_NEAR(v, f(u[0], u[1], u[2]), 1e-5f);
  }
  // Bricks that disagree (brick b answers b): along a line through faces the blend moves by at most
  // (the largest difference) x (step / ghost) per step: no jump at a face.
  float prev = -1;
  const float step = 1e-3f;
  for (float x = 0.0005f; x < 1; x += step) {
    const float v = l.blend_point(x, 0.49f, 0.51f, [](int b, float, float, float) { return float(b); });
    if (prev >= 0) ASSERT_LE(std::fabs(v - prev), 11.f * step * 30.f / 3.f + 1e-4f) << "x " << x;
    prev = v;
  }
}

// ---- training, resume, opening ----------------------------------------------------------------------

std::vector<uint16_t> brick_params(const std::string& dir, int index) {
  return load_model(join_path(dir, fmt::format("brick_{:05d}.vnr", index))).net->params_half();
}

TEST(BrickTraining, SameSeedSameBricksInAnyOrderAndResumeTrainsOnlyMissingOrDamagedBricks) {
  TmpDir tmp;
  const std::string vol = tmp / "v.json";
  synth_volume("marschner-lobb", Int3{24, 16, 12}, vol);
  const TrainingSetup s = test::small_brick_setup(vol);
  const BricksRunResult all = train_bricks(s, Int3{2, 1, 1}, 2, tmp / "a", test::brick_steps(20));
  EXPECT_TRUE(all.complete);
  EXPECT_EQ(all.trained.size(), 2u);
  // Brick 1 first, then brick 0, into another directory: the same parameters bit for bit.
  const std::string b = tmp / "b";
  prepare_brick_dir(b, all.plan, false);
  for (int i : {1, 0}) train_brick(s, all.plan, i, b, all.range, test::brick_steps(20).brick);
  for (int i : {0, 1}) EXPECT_EQ(brick_params(b, i), brick_params(tmp / "a", i)) << "brick " << i;
  EXPECT_NE(brick_params(b, 0), brick_params(b, 1));

  // Without --resume an existing model is never overwritten.
  EXPECT_HAS(test::error_of([&] { train_bricks(s, Int3{2, 1, 1}, 2, tmp / "a", test::brick_steps(20)); }), "--resume");
  // A different plan is refused on resume.
  BricksRunOptions resume = test::brick_steps(20);
  resume.resume = true;
  EXPECT_HAS(test::error_of([&] { train_bricks(s, Int3{1, 2, 1}, 2, tmp / "a", resume); }), "was started with");
  // Nothing missing: nothing trained.
  EXPECT_EQ(train_bricks(s, Int3{2, 1, 1}, 2, tmp / "a", resume).trained.size(), 0u);
  // A damaged brick (one flipped byte) and a missing one are trained again, to the same parameters.
  const std::vector<uint16_t> p0 = brick_params(tmp / "a", 0), p1 = brick_params(tmp / "a", 1);
  {
    std::fstream f(tmp / "a/brick_00000.vnr", std::ios::in | std::ios::out | std::ios::binary);
    f.seekg(-40, std::ios::end);
    char c = 0;
    f.read(&c, 1);
    c ^= 0x10;
    f.seekp(-40, std::ios::end);
    f.write(&c, 1);
  }
  EXPECT_HAS(test::error_of([&] { load_model(tmp / "a"); }), "--resume");
  EXPECT_EQ(bricks_done(tmp / "a", all.plan, s.config_json->dump()), (std::vector<bool>{false, true}));
  const BricksRunResult r = train_bricks(s, Int3{2, 1, 1}, 2, tmp / "a", resume);
  ASSERT_EQ(r.trained.size(), 1u);
  EXPECT_EQ(r.trained[0].index, 0);
  EXPECT_EQ(r.already_done, 1);
  EXPECT_EQ(brick_params(tmp / "a", 0), p0);
  // A stop during a brick (Ctrl-C): that brick's file is kept but incomplete, no later brick starts, and
  // --resume trains it again.
  std::atomic<bool> stop{false};
  BricksRunOptions stopping = test::brick_steps(20);
  stopping.brick.stop = &stop;
  stopping.brick.on_step = [&](const TrainingProgress& pr) { stop.store(pr.step >= 5); };
  const BricksRunResult cut = train_bricks(s, Int3{2, 1, 1}, 2, tmp / "c", stopping);
  EXPECT_TRUE(cut.interrupted);
  EXPECT_FALSE(cut.complete);
  ASSERT_EQ(cut.trained.size(), 1u);
  EXPECT_LT(cut.trained[0].steps, 20);
  EXPECT_TRUE(file_exists(tmp / "c/brick_00000.vnr"));
  EXPECT_FALSE(file_exists(tmp / "c/brick_00001.vnr"));
  EXPECT_EQ(bricks_done(tmp / "c", all.plan, s.config_json->dump()), (std::vector<bool>{false, false}));
  const BricksRunResult finished = train_bricks(s, Int3{2, 1, 1}, 2, tmp / "c", resume);
  EXPECT_EQ(finished.trained.size(), 2u);
  EXPECT_EQ(brick_params(tmp / "c", 0), p0);

  std::filesystem::remove(tmp / "a/brick_00001.vnr");
  EXPECT_HAS(test::error_of([&] { load_model(tmp / "a"); }), "brick 1 (brick_00001.vnr) is missing");
  EXPECT_EQ(train_bricks(s, Int3{2, 1, 1}, 2, tmp / "a", resume).trained.size(), 1u);
  EXPECT_EQ(brick_params(tmp / "a", 1), p1);
}

// Error-jump across the plane between x = i - 1 and i: mean over the plane of |e(i) - e(i-1)|, e = decode - truth.
double error_jump_x(const std::vector<float>& dec, const Volume& truth, int64_t i) {
  const Int3 d = truth.dims;
  double s = 0;
  for (int64_t z = 0; z < d.z; ++z)
    for (int64_t y = 0; y < d.y; ++y) {
      const size_t a = size_t(i - 1 + d.x * (y + d.y * z)), b = a + 1;
      s += std::fabs((dec[b] - truth.data[b]) - (dec[a] - truth.data[a]));
    }
  return s / double(d.y * d.z);
}

double psnr_where(const std::vector<float>& dec, const Volume& truth, const std::function<bool(int64_t x)>& keep) {
  double se = 0;
  int64_t n = 0;
  for (size_t v = 0; v < dec.size(); ++v)
    if (keep(int64_t(v) % truth.dims.x)) {
      se += double(dec[v] - truth.data[v]) * (dec[v] - truth.data[v]);
      ++n;
    }
  return 10 * std::log10(double(n) / se);
}

TEST(BrickTraining, QualityMatchesOneModelOfTheSameSizeWithAccurateFacesAndNoSeam) {
  TmpDir tmp;
  const Int3 dims{48, 24, 24};
  const std::string vol = tmp / "v.json";
  synth_volume("marschner-lobb", dims, vol);
  TrainingSetup s = test::small_brick_setup(vol);
  s.target_ratio = 6;  // the whole model's: both get the same parameter budget
  const BricksRunResult br = train_bricks(s, Int3{2, 1, 1}, 4, tmp / "m", test::brick_steps(250));
  ASSERT_TRUE(br.complete);
  s.session.output = tmp / "one.vnr";
  s.steps = 500;  // the bricks' steps together
  auto session = open_training_session(s);
  session->run(500);
  session->finish({.ssim = false});

  const Volume truth = open_volume(vol);
  const Model multi = load_model(tmp / "m"), one = load_model(tmp / "one.vnr");
  const double multi_bytes = double(multi.bricks->param_bytes()), one_bytes = double(one.param_bytes());
  EXPECT_NEAR(multi_bytes / one_bytes, 1.0, 0.3);
  const Volume dm = ModelQuery(multi, Device::Cpu).decode(), d1 = ModelQuery(one, Device::Cpu).decode();
  const std::vector<float> vm(dm.data.begin(), dm.data.end()), v1(d1.data.begin(), d1.data.end());
  const double psnr_multi = error_stats(truth.data.data(), vm.data(), dims).psnr;
  const double psnr_one = error_stats(truth.data.data(), v1.data(), dims).psnr;
  EXPECT_GT(psnr_multi, psnr_one - 1.0) << "multi " << psnr_multi << " one " << psnr_one;
  // Voxels next to the face (x = 23, 24) against the rest.
  const int64_t face = br.plan.bricks[1].owned.lo.x;
  const double at_face = psnr_where(vm, truth, [&](int64_t x) { return x == face - 1 || x == face; });
  const double inside = psnr_where(vm, truth, [&](int64_t x) { return x < face - 4 || x >= face + 4; });
  EXPECT_GT(at_face, inside - 1.0) << "face " << at_face << " inside " << inside;
  // The seam: the error's jump across the face against its mean jump across interior planes, and
  // against the same bricks trained without a ghost layer (whose faces do show a seam).
  double interior_jump = 0;
  int planes = 0;
  for (int64_t i = 2; i < dims.x - 1; ++i)
    if (std::abs(i - face) > 4) interior_jump += error_jump_x(vm, truth, i), ++planes;
  interior_jump /= planes;
  const double face_jump = error_jump_x(vm, truth, face);
  s.session.output.clear();
  train_bricks(s, Int3{2, 1, 1}, 0, tmp / "g0", test::brick_steps(250));
  const Volume d0 = ModelQuery(load_model(tmp / "g0"), Device::Cpu).decode();
  const double face_jump_g0 = error_jump_x(std::vector<float>(d0.data.begin(), d0.data.end()), truth, face);
  std::printf("multi %.2f dB (face %.2f, inside %.2f; error jump at the face %.4f, interior mean %.4f, ghost 0 "
              "%.4f), one model %.2f dB\n",
              psnr_multi, at_face, inside, face_jump, interior_jump, face_jump_g0, psnr_one);
  EXPECT_LE(face_jump, interior_jump);
  EXPECT_LT(face_jump, 0.5 * face_jump_g0);
}

// The regions of an MPI eval (any boxes tiling the volume: here the bricks' owned boxes and an uneven
// split, also with a region thinner than the SSIM window) add up to evaluate() of the whole decode: the
// same PSNR, max error and SSIM, whose windows cross every region's faces.
TEST(BrickModel, RegionEvaluationsAddUpToTheWholeEvaluation) {
  TmpDir tmp;
  const Int3 dims{23, 19, 17};
  const std::string vol = tmp / "v.json";
  synth_volume("marschner-lobb", dims, vol);
  train_bricks(test::small_brick_setup(vol), Int3{3, 2, 2}, 2, tmp / "m", test::brick_steps(20));
  const Model m = load_model(tmp / "m");
  const Volume truth = open_volume(vol);
  const EvalResult full = evaluate(m, truth, true);
  const RawVolumeFile file(describe_volume(vol), truth.lo, truth.hi, NonFinitePolicy::Error);
  std::vector<Box3> owned;
  for (const BrickSpec& b : m.bricks->plan.bricks) owned.push_back(b.owned);
  // [20, 23) in x: no window starts there (its grid is narrower than a window).
  const std::vector<Box3> uneven = {Box3{{0, 0, 0}, {4, 19, 17}},   Box3{{4, 0, 0}, {20, 3, 17}},
                                    Box3{{20, 0, 0}, {23, 3, 17}}, Box3{{4, 3, 0}, {23, 19, 9}},
                                    Box3{{4, 3, 9}, {23, 19, 17}}};
  for (const std::vector<Box3>& tiling : {owned, uneven}) {
    for (bool with_ssim : {true, false}) {
      EvalSums all;
      for (const Box3& r : tiling) all.add(evaluate_region(m, file, r, with_ssim, 3 * 23 * 19));
      const EvalResult got = all.result(truth.hi - truth.lo);
      EXPECT_EQ(all.voxels, int64_t(dims.count()));
      EXPECT_NEAR(got.psnr, full.psnr, 1e-9 * full.psnr);
      EXPECT_EQ(got.max_abs_error, full.max_abs_error);
      if (with_ssim) {
        EXPECT_EQ(all.ssim_windows, int64_t(17 * 13 * 11));
        EXPECT_NEAR(got.ssim, full.ssim, 1e-12);
      } else {
        EXPECT_EQ(all.ssim_windows, 0);
      }
    }
  }
}

TEST(BrickModel, EveryPathOpensTheDirectoryLikeOneModel) {
  TmpDir tmp;
  const Int3 dims{20, 16, 12};
  const std::string vol = tmp / "v.json";
  synth_volume("marschner-lobb", dims, vol);
  train_bricks(test::small_brick_setup(vol), Int3{2, 2, 1}, 2, tmp / "m", test::brick_steps(30));
  const Model m = load_model(tmp / "m");
  ASSERT_TRUE(m.bricks);
  EXPECT_EQ(m.dims, dims);
  // One interface (ModelForm): what differs by kind is answered by the bricks' form, and a single network
  // (a brick's own file) by the network's.
  EXPECT_EQ(&form_of(m), &bricks_form());
  const Model brick0 = load_model(tmp / "m/brick_00000.vnr");
  EXPECT_EQ(&form_of(brick0), &network_form());
  uint64_t summed = 0;
  for (const auto& b : m.bricks->bricks) summed += b->net->n_params();
  EXPECT_EQ(m.n_params(), summed);
  EXPECT_FALSE(m.trainable());
  EXPECT_TRUE(brick0.trainable());
  EXPECT_EQ(evaluation_device(m, Device::Cuda), Device::Cpu);  // multi-brick evaluations run on the CPU
  test::expect_error([&] { save_model(tmp / "one.vnr", m); }, {"a multi-brick model is a directory of brick files"});
  EXPECT_FALSE(file_exists(tmp / "one.vnr"));
  ModelQuery q(m, Device::Cpu);
  // Points at voxel centres = the slab decode = the region decode, at another resolution too.
  for (Int3 d : {dims, Int3{13, 21, 7}}) {
    std::vector<float> slab(d.count()), xyz, pts(d.count()), region(size_t(d.x * d.y * 2));
    q.slab(d, 0, d.z, slab.data());
    for (int64_t v = 0; v < int64_t(d.count()); ++v) {
      float x, y, z;
      voxel_centre(d, v, &x, &y, &z);
      xyz.insert(xyz.end(), {x, y, z});
    }
    q.points(xyz.data(), int64_t(d.count()), pts.data());
    EXPECT_EQ(slab, pts);
    decode_bricked_region(*m.bricks, d, Box3{{0, 0, 3}, {d.x, d.y, 5}}, region.data());
    EXPECT_TRUE(std::equal(region.begin(), region.end(), slab.begin() + 3 * d.x * d.y));
  }
  // evaluate_model_file: the PSNR of that decode against the volume.
  const Volume truth = open_volume(vol);
  const Volume dec = q.decode();
  FileEvalOptions o;
  o.model_path = tmp / "m";
  const FileEvaluation ev = evaluate_model_file(m, vol, o);
  EXPECT_NEAR(ev.psnr, error_stats(truth.data.data(), dec.data.data(), dims).psnr, 1e-9);
  EXPECT_EQ(ev.model_bytes, model_file_bytes(tmp / "m"));
  o.samples = 4000;  // sampled: through the same blended decode
  EXPECT_NEAR(evaluate_model_file(m, vol, o).psnr, ev.psnr, 1.5);
  // Rendering: the streaming strategy (batched blend) and the in-shader one (per-point blend) agree.
  // On the CPU (the GPU draws the model's decode: test_gpu_paths); auto picks the CPU without a GPU.
  if (cuda::devices().empty()) EXPECT_EQ(choose_render_device("auto", &m), Device::Cpu);
  Renderer r(m, Device::Cpu);
  r.set_size(48, 40);
  r.set_strategy(RenderStrategy::Streaming);
  const Image a = r.render_frame();
  r.set_strategy(RenderStrategy::InShader);
  const Image b = r.render_frame();
  double diff = 0, sum = 0;
  for (size_t i = 0; i < a.pixels.size(); ++i) {
    diff = std::max(diff, double(std::fabs(a.pixels[i].x - b.pixels[i].x)));
    sum += a.pixels[i].w;
  }
  EXPECT_GT(sum, 10.0);  // something is drawn
  EXPECT_LT(diff, 2e-3);
  EXPECT_TRUE(m.macrocells);  // the bricks' ranges merged over the volume

  // Sort-last: every brick's segment composited in per-pixel depth order = the whole frame, with and
  // without gradient shading (whose neighbour points reach across faces).
  for (bool shade : {false, true}) {
    r.set_shading(shade);
    r.set_background(Vec3f{0.2f, 0.3f, 0.4f});
    const Image whole = r.render_frame();
    std::vector<BrickSegment> segs;
    for (int i = 0; i < 4; ++i) segs.push_back(render_brick_segment(r, i));
    std::vector<const BrickSegment*> ptrs;
    for (const BrickSegment& sg : segs) ptrs.push_back(&sg);
    const Image comp = composite_brick_segments(ptrs, Vec3f{0.2f, 0.3f, 0.4f});
    double worst = 0;
    for (size_t i = 0; i < whole.pixels.size(); ++i) {
      const Vec4f a = whole.pixels[i], b = comp.pixels[i];
      for (float d : {a.x - b.x, a.y - b.y, a.z - b.z, a.w - b.w}) worst = std::max(worst, double(std::fabs(d)));
    }
    EXPECT_LT(worst, 1e-4) << "shade " << shade;
  }
  r.set_mode(RenderMode::PathTrace);
  EXPECT_HAS(test::error_of([&] { render_brick_segment(r, 0); }), "ray marching");
}

TEST(BrickModel, TheViewerShowsItAsTheRendererDoes) {
  TmpDir tmp;
  const std::string vol = tmp / "v.json";
  synth_volume("marschner-lobb", Int3{16, 16, 16}, vol);
  train_bricks(test::small_brick_setup(vol), Int3{1, 2, 1}, 2, tmp / "m", test::brick_steps(20));
  ViewerSetup setup;
  setup.input = tmp / "m";
  setup.device = "auto";  // the CPU for a multi-brick model
  ViewerEngine engine(setup);
  EXPECT_FALSE(engine.info().can_train);  // viewed, not retrained
  EXPECT_EQ(engine.info().n_params, int64_t(load_model(tmp / "m").n_params()));
  ViewerRender vr = engine.state().render;
  vr.max_frames = 1;
  engine.set_viewport(64, 48);
  engine.set_render(vr);
  std::shared_ptr<const ViewerFrame> f;
  for (uint64_t last = 0; !f;) {
    auto g = engine.wait_frame(last, 30);
    ASSERT_TRUE(g);
    last = g->id;
    if (g->refined && g->accumulated == 1 && !g->images.empty() && g->images[0].width == 64 &&
        g->cache_bricks > 0 && g->cache_pending == 0 && g->cache_stale == 0)
      f = g;
  }
  while (auto more = engine.wait_frame(f->id, 1.0)) f = more;  // until every brick the view reads is in
  const ViewerState st = engine.state();
  const RenderInput input = open_render_input(setup.input, "", {}, parse_precision("auto"));
  Renderer r(*input.model, Device::Cpu);
  r.set_scene(input.scene);
  r.set_camera(st.camera);
  r.set_transfer_function(to_transfer_function(st.tf));
  r.set_size(st.width, st.height);
  r.choose_strategy("cache");  // the viewer draws a model on the CPU from its brick cache
  r.warm_cache();
  r.render_frame();
  EXPECT_EQ(f->images[0].rgba, to_rgba8(r.image()));
}

#ifdef VNR_CLI_PATH
TEST(BrickCli, TrainInfoDecodeAndErrors) {
  TmpDir tmp;
  test::run("synth marschner-lobb --dims 16,16,16 -o " + tmp / "v.json");
  const std::string cfg = tmp / "c.json";
  write_file_atomic(cfg, test::small_hash_config(8, 16, 1).dump());
  const std::string train = "train " + tmp / "v.json" + " --config " + cfg + " --steps 10 --batch 1024 --no-ssim -q --bricks 2,1,1 --ghost 2 -o " + tmp / "m";
  test::Result t = test::run(train);
  ASSERT_EQ(t.code, 0) << t.err;
  EXPECT_HAS(t.out, "PSNR");
  test::Result info = test::run("info --json " + tmp / "m");
  ASSERT_EQ(info.code, 0) << info.err;
  const Json j = Json::parse(info.out);
  EXPECT_EQ(j["format"], "vnr-bricks");
  EXPECT_EQ(j["bricks"]["count"], 2);
  EXPECT_EQ(j["n_params"].get<uint64_t>(), 2 * load_model(tmp / "m/brick_00000.vnr").net->n_params());
  EXPECT_EQ(test::run("decode " + tmp / "m" + " -o " + tmp / "d.raw --dims 8,8,8 -q").code, 0);
  EXPECT_EQ(file_size(tmp / "d.raw"), 8u * 8 * 8 * 4);
  test::expect_error(train, "--resume");
  test::expect_error("train " + tmp / "v.json" + " --bricks 9,1,1 --ghost 2 -q -o " + tmp / "n", "at most");
  test::expect_error("train " + tmp / "v.json" + " --bricks 2,1,1 -q -o " + tmp / "n.vnr", "directory");
  EXPECT_EQ(test::run(train + " --resume").code, 0);
}

// --seconds limits each brick by time, as under mpirun: every brick trains about that long, and the
// manifest records no fixed step count.
TEST(BrickCli, SecondsApplyPerBrick) {
  TmpDir tmp;
  test::run("synth marschner-lobb --dims 16,16,16 -o " + tmp / "v.json");
  const std::string cfg = tmp / "c.json";
  write_file_atomic(cfg, test::small_hash_config(8, 16, 1).dump());
  test::Result t = test::run("train " + tmp / "v.json" + " --config " + cfg +
                             " --seconds 0.4 --batch 1024 --threads 1 --no-ssim -q --bricks 2,1,1 --ghost 2 -o " + tmp / "m");
  ASSERT_EQ(t.code, 0) << t.err;
  const Json manifest = parse_json_file(tmp / "m/manifest.json");
  EXPECT_TRUE(manifest["training"]["steps_per_brick"].is_null());
  for (const char* brick : {"m/brick_00000.vnr", "m/brick_00001.vnr"}) {
    const Model m = load_model(tmp / brick);
    EXPECT_GE(m.training.value("seconds", 0.0), 0.4) << brick;
    EXPECT_LT(m.training.value("seconds", 0.0), 5.0) << brick;
    EXPECT_GT(m.training.value("steps", int64_t(0)), 1) << brick;
  }
}
#endif

TEST(BrickModel, RankSharesTileTheGridAndLoadTheirNeighbours) {
  TmpDir tmp;
  const std::string vol = tmp / "v.json";
  synth_volume("marschner-lobb", Int3{16, 16, 16}, vol);
  train_bricks(test::small_brick_setup(vol), Int3{2, 2, 1}, 2, tmp / "m", test::brick_steps(2));
  for (const Int3 dims : {Int3{16, 16, 16}, Int3{9, 13, 5}}) {
    int64_t voxels = 0;
    for (int rank = 0; rank < 3; ++rank) {
      const BrickShare share = open_brick_share(tmp / "m", dims, 1, rank, 3);
      for (const Box3& r : share.regions) voxels += r.voxels();
      int loaded = 0;
      for (const auto& b : share.model->bricks) loaded += b.has_value();
      EXPECT_EQ(size_t(loaded), share.loaded);
      EXPECT_GE(share.loaded, share.regions.size()) << "its bricks, and neighbours within reach";
    }
    EXPECT_EQ(voxels, dims.count()) << "the ranks' regions tile the grid";
  }
  int idle = 0;  // more ranks than bricks: some have none (and load nothing of their own)
  int64_t voxels = 0;
  for (int rank = 0; rank < 8; ++rank) {
    const BrickShare share = open_brick_share(tmp / "m", Int3{16, 16, 16}, 1, rank, 8);
    for (const Box3& r : share.regions) voxels += r.voxels();
    if (!share.regions.empty()) continue;
    idle += 1;
    EXPECT_EQ(share.loaded, 0u);
  }
  EXPECT_EQ(idle, 4);
  EXPECT_EQ(voxels, int64_t(16 * 16 * 16));
}

}  // namespace
}  // namespace vnr
