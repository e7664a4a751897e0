// Brick plans, their assignment to ranks, seeds, the manifest and which bricks are done (train/bricks.h).
#include "vnr/train/bricks.h"
#include <algorithm>
#include <filesystem>
#include <numeric>
#include "vnr/error.h"
#include "vnr/fileio.h"

namespace vnr {

namespace fs = std::filesystem;

Int3 parse_brick_grid(const std::string& text) {
  if (text == "auto") return Int3{0, 0, 0};
  std::vector<std::string> parts{""};
  for (char c : text) {
    if (c == ',') parts.emplace_back();
    else parts.back().push_back(c);
  }
  Int3 g;
  bool ok = parts.size() == 3;
  for (size_t i = 0; ok && i < 3; ++i) {
    try {
      size_t used = 0;
      g[int(i)] = std::stoll(parts[i], &used);
      ok = used == parts[i].size() && g[int(i)] >= 1;
    } catch (const std::exception&) {
      ok = false;
    }
  }
  if (!ok) fail("--bricks expects BX,BY,BZ (positive integers) or auto, got '{}'", text);
  return g;
}

namespace {

// Halves the brick along its longest axis until each holds at most auto_brick_voxels voxels.
Int3 auto_grid(Int3 dims) {
  Int3 g{1, 1, 1};
  auto brick_voxels = [&] {
    uint64_t v = 1;
    for (int i = 0; i < 3; ++i) v *= uint64_t((dims[i] + g[i] - 1) / g[i]);
    return v;
  };
  while (brick_voxels() > auto_brick_voxels) {
    int axis = 0;
    for (int i = 1; i < 3; ++i)
      if ((dims[i] + g[i] - 1) / g[i] > (dims[axis] + g[axis] - 1) / g[axis]) axis = i;
    g[axis] *= 2;
  }
  return g;
}

// Start of part k of n parts of length len: the first len % n parts are one longer.
int64_t split_at(int64_t len, int64_t n, int64_t k) { return k * (len / n) + std::min(k, len % n); }

const char* axis_name(int i) { return i == 0 ? "x" : (i == 1 ? "y" : "z"); }

}  // namespace

uint32_t brick_seed(uint32_t seed, int index) {
  // splitmix64 of (seed, index): independent streams per brick, the same whichever rank trains it.
  uint64_t z = (uint64_t(seed) << 32) ^ uint64_t(uint32_t(index)) ^ 0x9E3779B97F4A7C15ULL;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  z ^= z >> 31;
  return uint32_t(z ^ (z >> 32));
}

BrickPlan plan_bricks(Int3 dims, Int3 grid, int ghost, uint32_t seed) {
  if (dims.x < 1 || dims.y < 1 || dims.z < 1) fail("cannot split a {}x{}x{} volume into bricks", dims.x, dims.y, dims.z);
  if (ghost < 0) fail("--ghost must be non-negative, got {}", ghost);
  if (grid == Int3{0, 0, 0}) grid = auto_grid(dims);
  for (int i = 0; i < 3; ++i) {
    if (grid[i] < 1) fail("--bricks: the brick count along {} must be positive, got {}", axis_name(i), grid[i]);
    const int64_t most = std::max<int64_t>(1, dims[i] / (ghost + 1));
    if (grid[i] > most)
      fail("--bricks: {} bricks along {} are too many for {} voxels with --ghost {} (at most {}: each brick needs "
           "more voxels than the ghost layer)",
           grid[i], axis_name(i), dims[i], ghost, most);
  }
  BrickPlan plan;
  plan.dims = dims;
  plan.grid = grid;
  plan.ghost = ghost;
  plan.seed = seed;
  for (int64_t k = 0; k < grid.z; ++k)
    for (int64_t j = 0; j < grid.y; ++j)
      for (int64_t i = 0; i < grid.x; ++i) {
        BrickSpec b;
        b.index = int(plan.bricks.size());
        b.coord = Int3{i, j, k};
        for (int a = 0; a < 3; ++a) {
          b.owned.lo[a] = split_at(dims[a], grid[a], b.coord[a]);
          b.owned.hi[a] = split_at(dims[a], grid[a], b.coord[a] + 1);
          b.trained.lo[a] = std::max<int64_t>(0, b.owned.lo[a] - ghost);
          b.trained.hi[a] = std::min<int64_t>(dims[a], b.owned.hi[a] + ghost);
        }
        b.seed = brick_seed(seed, b.index);
        b.file = fmt::format("brick_{:05d}.vnr", b.index);
        plan.bricks.push_back(b);
      }
  return plan;
}

std::vector<std::vector<int>> assign_bricks(const BrickPlan& plan, int n_ranks) {
  if (n_ranks < 1) fail("assign_bricks: {} ranks", n_ranks);
  std::vector<int> order(plan.bricks.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return plan.bricks[size_t(a)].trained.voxels() > plan.bricks[size_t(b)].trained.voxels();
  });
  std::vector<uint64_t> load(size_t(n_ranks), 0);
  std::vector<std::vector<int>> out(static_cast<size_t>(n_ranks));
  for (int b : order) {
    const size_t r = size_t(std::min_element(load.begin(), load.end()) - load.begin());  // first least loaded
    load[r] += plan.bricks[size_t(b)].trained.voxels();
    out[r].push_back(b);
  }
  for (auto& v : out) std::sort(v.begin(), v.end());
  return out;
}

std::vector<int> contiguous_bricks(const BrickPlan& plan, int rank, int n_ranks) {
  if (n_ranks < 1 || rank < 0 || rank >= n_ranks) fail("contiguous_bricks: rank {} of {}", rank, n_ranks);
  uint64_t total = 0;
  for (const BrickSpec& b : plan.bricks) total += b.owned.voxels();
  // A brick goes to the rank whose share of the voxels holds the brick's middle voxel.
  std::vector<int> out;
  uint64_t before = 0;
  for (const BrickSpec& b : plan.bricks) {
    const uint64_t middle = before + b.owned.voxels() / 2;
    before += b.owned.voxels();
    const uint64_t owner = total ? std::min<uint64_t>(middle * uint64_t(n_ranks) / total, uint64_t(n_ranks - 1)) : 0;
    if (owner == uint64_t(rank)) out.push_back(b.index);
  }
  return out;
}

Box3 brick_output_region(const BrickPlan& plan, int index, Int3 out_dims) {
  if (index < 0 || size_t(index) >= plan.bricks.size()) fail("brick {} is not in the plan", index);
  const Box3& owned = plan.bricks[size_t(index)].owned;
  Box3 r;
  for (int a = 0; a < 3; ++a) {
    if (out_dims[a] < 1) fail("output dims must be positive, got {}", out_dims[a]);
    // Voxel i's centre (i + 1/2) * dims / out lies at or past p exactly when
    // (2i + 1) * dims >= 2 p * out, i.e. i >= ceil((2 p out - dims) / (2 dims)).
    auto first_at_or_past = [&](int64_t p) {
      const int64_t num = 2 * p * out_dims[a] - plan.dims[a], den = 2 * plan.dims[a];
      const int64_t q = num >= 0 ? (num + den - 1) / den : -((-num) / den);
      return std::clamp<int64_t>(q, 0, out_dims[a]);
    };
    r.lo[a] = first_at_or_past(owned.lo[a]);
    r.hi[a] = std::max(r.lo[a], first_at_or_past(owned.hi[a]));
  }
  return r;
}

std::vector<int> bricks_touching(const BrickPlan& plan, const Box3& region) {
  std::vector<int> out;
  for (const BrickSpec& b : plan.bricks)
    if (!intersect(b.trained, region).empty()) out.push_back(b.index);
  return out;
}

namespace {

Json box_json(const Box3& b) { return Json{{"lo", {b.lo.x, b.lo.y, b.lo.z}}, {"hi", {b.hi.x, b.hi.y, b.hi.z}}}; }

Box3 box_of(const Json& j, const std::string& where) {
  Box3 b;
  try {
    for (int i = 0; i < 3; ++i) {
      b.lo[i] = j.at("lo").at(size_t(i)).get<int64_t>();
      b.hi[i] = j.at("hi").at(size_t(i)).get<int64_t>();
    }
  } catch (const std::exception&) {
    fail("{}: a brick box must be {{\"lo\": [x, y, z], \"hi\": [x, y, z]}}", where);
  }
  return b;
}

}  // namespace

Json brick_record(const BrickSpec& b) {
  return Json{{"index", b.index}, {"coord", {b.coord.x, b.coord.y, b.coord.z}}, {"owned", box_json(b.owned)},
              {"trained", box_json(b.trained)}, {"seed", b.seed}, {"file", b.file}};
}

void write_manifest(const std::string& out_dir, const BrickPlan& plan, DType dtype, const ValueRange& range,
                    const Json& config, const std::vector<BrickResult>& results, const Json& training) {
  Json bricks = Json::array();
  for (const BrickSpec& b : plan.bricks) {
    Json j = brick_record(b);
    for (const BrickResult& r : results)
      if (r.index == b.index)
        j["training"] = {{"steps", r.steps}, {"seconds", r.seconds}, {"final_loss", r.final_loss},
                         {"psnr", r.psnr},   {"n_params", r.n_params}, {"file_bytes", r.file_bytes}};
    bricks.push_back(j);
  }
  const Json m = {{"format", "vnr-bricks"},
                  {"version", 1},
                  {"dims", {plan.dims.x, plan.dims.y, plan.dims.z}},
                  {"dtype", dtype_name(dtype)},
                  {"value_range", {range.lo, range.hi}},
                  {"grid", {plan.grid.x, plan.grid.y, plan.grid.z}},
                  {"ghost", plan.ghost},
                  {"seed", plan.seed},
                  {"blend", "linear-ghost"},
                  {"config", config},
                  {"training", training},
                  {"bricks", bricks}};
  write_file_atomic(join_path(out_dir, "manifest.json"), m.dump(2) + "\n");
}

BrickPlan read_manifest_plan(const Json& m, const std::string& where) {
  if (!m.is_object() || m.value("format", "") != "vnr-bricks")
    fail("{}: not a multi-brick manifest (\"format\": \"vnr-bricks\" expected)", where);
  if (m.value("version", 0) != 1) fail("{}: manifest version {} is not supported (this vnr reads 1)", where, m.value("version", 0));
  BrickPlan p;
  try {
    for (int i = 0; i < 3; ++i) {
      p.dims[i] = m.at("dims").at(size_t(i)).get<int64_t>();
      p.grid[i] = m.at("grid").at(size_t(i)).get<int64_t>();
    }
    p.ghost = m.at("ghost").get<int>();
    p.seed = m.at("seed").get<uint32_t>();
  } catch (const std::exception&) {
    fail("{}: the manifest needs dims, grid, ghost and seed", where);
  }
  // The manifest must describe exactly the plan these numbers give (the blend depends on the boxes).
  BrickPlan want = plan_bricks(p.dims, p.grid, p.ghost, p.seed);
  const Json& bricks = m.contains("bricks") ? m["bricks"] : Json();
  if (!bricks.is_array() || bricks.size() != want.bricks.size())
    fail("{}: the manifest lists {} bricks, its grid needs {}", where, bricks.is_array() ? bricks.size() : 0,
         want.bricks.size());
  for (size_t i = 0; i < bricks.size(); ++i) {
    const std::string bw = fmt::format("{}: brick {}", where, i);
    BrickSpec& b = want.bricks[i];
    if (!(box_of(bricks[i].value("owned", Json()), bw) == b.owned) ||
        !(box_of(bricks[i].value("trained", Json()), bw) == b.trained))
      fail("{}: its boxes do not match the grid {}x{}x{} with ghost {}", bw, p.grid.x, p.grid.y, p.grid.z, p.ghost);
    const std::string file = bricks[i].value("file", "");
    if (file.empty() || file.find('/') != std::string::npos || file == "." || file == "..")
      fail("{}: a brick file must be a plain file name in the model directory, got '{}'", bw, file);
    b.file = file;
  }
  return want;
}

bool is_bricked_model_dir(const std::string& path) {
  std::error_code ec;
  return fs::is_directory(path, ec) && fs::is_regular_file(join_path(path, "manifest.json"), ec);
}

uint64_t model_file_bytes(const std::string& path) {
  if (!is_bricked_model_dir(path)) return file_size(path);
  const BrickPlan plan = read_manifest_plan(parse_json_file(join_path(path, "manifest.json")), path);
  uint64_t n = file_size(join_path(path, "manifest.json"));
  for (const BrickSpec& b : plan.bricks) n += file_size(join_path(path, b.file));
  return n;
}

std::vector<bool> bricks_done(const std::string& out_dir, const BrickPlan& plan, const std::string& config_text) {
  std::vector<bool> done(plan.bricks.size(), false);
  for (const BrickSpec& b : plan.bricks) {
    const std::string path = join_path(out_dir, b.file);
    if (!file_exists(path)) continue;
    try {
      const Model m = load_model(path);  // checks the CRC and the parameter count
      const Json& rec = m.training.is_object() ? m.training.value("brick", Json()) : Json();
      done[size_t(b.index)] = m.dims == b.trained.size() && rec.is_object() && rec.value("complete", false) &&
                              rec.value("seed", uint32_t(0)) == b.seed &&
                              (config_text.empty() || rec.value("config", std::string()) == config_text);
    } catch (const Error&) {
      // damaged: trained again
    }
  }
  return done;
}

BrickShare open_brick_share(const std::string& dir, Int3 dims, int reach, int rank, int n_ranks) {
  const std::vector<int> none;
  const BrickPlan plan = load_bricked_model(dir, &none)->plan;
  BrickShare share;
  std::vector<int> only;
  for (int b : contiguous_bricks(plan, rank, n_ranks)) {
    const Box3 region = brick_output_region(plan, b, dims);
    if (region.empty()) continue;
    share.regions.push_back(region);
    Box3 grown = plan.bricks[size_t(b)].owned;
    for (int a = 0; a < 3; ++a) {
      grown.lo[a] = std::max<int64_t>(0, grown.lo[a] - reach);
      grown.hi[a] = std::min<int64_t>(plan.dims[a], grown.hi[a] + reach);
    }
    for (int n : bricks_touching(plan, grown)) only.push_back(n);
  }
  std::sort(only.begin(), only.end());
  only.erase(std::unique(only.begin(), only.end()), only.end());
  share.loaded = only.size();
  if (only.empty()) only.push_back(0);
  share.model = load_bricked_model(dir, &only);
  return share;
}

}  // namespace vnr
