#include "vnr/fields/brick_cache.h"
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <new>
#include <omp.h>
#include "vnr/error.h"
#include "vnr/grid_view.h"
#include "vnr/core/parallel.h"
#include "vnr/progress.h"
#include "vnr/units.h"
#include "vnr/fields/grid_packets.h"
#include "vnr/render/inshader.h"

namespace vnr {

void check_cache_budget(uint64_t budget_bytes, int brick) {
  const double brick_bytes = std::pow(double(brick + 1), 3) * sizeof(float);
  if (double(budget_bytes) < brick_bytes)
    fail("a cache budget of {} holds no brick of {}^3 voxels ({})", human_bytes(double(budget_bytes)), brick + 1,
         human_bytes(brick_bytes));
}

float cache_lod_scale(const CameraFrame& c, Vec3f box, Int3 dims, float lod_pixels) {
  const Vec3f cell{box.x / float(dims.x), box.y / float(dims.y), box.z / float(dims.z)};
  const float voxel = std::max(cell.x, std::max(cell.y, cell.z));
  const float pixel_per_distance = length(c.dv) / float(std::max(1, c.height));
  return pixel_per_distance * lod_pixels / voxel;
}

namespace {
int64_t ceil_div(int64_t a, int64_t b) { return (a + b - 1) / b; }
}  // namespace

Int3 cache_level_dims(Int3 dims, int level) {
  const int64_t k = int64_t(1) << std::min(level, 62);
  return Int3{std::max<int64_t>(1, ceil_div(dims.x, k)), std::max<int64_t>(1, ceil_div(dims.y, k)),
              std::max<int64_t>(1, ceil_div(dims.z, k))};
}

uint64_t default_cache_budget() {
  const uint64_t quarter = available_memory_bytes() / 4;
  return std::clamp<uint64_t>(quarter, uint64_t(64) << 20, uint64_t(4) << 30);
}

uint64_t parse_cache_budget(const std::string& text) {
  if (text.empty() || text == "auto") return default_cache_budget();
  const uint64_t b = parse_byte_size(text);
  return b == 0 ? default_cache_budget() : b;
}

struct BrickKey {
  int level;
  int64_t brick;
  float distance;
};

namespace {
// One level of detail's storage (its view: CacheLevelView).
struct Level {
  Int3 n, nb;  // voxels, bricks per axis
  std::vector<int32_t> slot;
  std::unique_ptr<std::atomic<uint32_t>[]> used, asked;  // the last frame that read / asked for a brick
  int64_t bricks() const { return int64_t(nb.x) * nb.y * nb.z; }
  Int3 brick_coords(int64_t b) const { return Int3{b % nb.x, (b / nb.x) % nb.y, b / (nb.x * nb.y)}; }  // x fastest
};
}  // namespace

struct CachedField::State {
  std::vector<Level> levels;
  CameraFrame lod_cam{};             // the view lod was computed for
  Vec3f box{1, 1, 1};                // world size of the volume box of that view
  std::optional<std::pair<Vec3f, Vec3f>> focus;  // the cursor's ray: origin, unit direction
  std::unique_ptr<float[]> pool;     // slots of (B+1)^3 voxels, committed by the OS as they are written
  int32_t slots = 0, slots_used = 0;
  struct Resident {
    int level;
    int64_t brick;
    int32_t slot;
    uint32_t generation;  // of the model it was decoded from
  };
  uint32_t generation = 0;  // grows with replace_source(..., true)
  uint64_t version = 0;     // grows with every brick decoded
  std::vector<Resident> resident;
  std::mutex asked_mutex;
  std::vector<BrickKey> asked;       // bricks asked for since the last begin_frame
  BrickCacheView view;
  // A renderer's copy of the cache (take_changes): the slots written and page-table entries set since
  // it was last brought up to date, recorded only while there is one. Untaken (a copy no longer drawn),
  // they are compacted as they grow (one per slot, the last entry per brick), so they stay bounded.
  bool copied = false;
  std::vector<int32_t> written;
  std::vector<std::pair<int64_t, int32_t>> moved;
  size_t written_limit = 0, moved_limit = 0;
  BrickCacheStats totals;
  std::atomic<int64_t> misses{0};
  // The decoding thread (set_asynchronous): its jobs in priority order (the back first), the bricks it
  // finished (begin_frame installs them), whether one is in flight, and the first error it met.
  // decode_mu serialises calls of the decode (the decoding thread's and the frame's own).
  struct Job {
    int level;
    int64_t brick;
    uint32_t generation;
  };
  struct Decoded {
    Job job;
    std::vector<float> voxels;
  };
  bool async = false;  // read and written by the thread that renders
  std::thread worker;
  std::mutex work_mu, decode_mu;
  std::condition_variable work_cv, done_cv;
  std::vector<Job> jobs;
  std::vector<Decoded> decoded;
  bool in_flight = false, stopping = false;
  std::string error;

  static void ask(void* self, int l, int64_t b) {
    State& s = *static_cast<State*>(self);
    Level& L = s.levels[size_t(l)];
    const uint32_t frame = s.view.frame;
    if (L.asked[b].load(std::memory_order_relaxed) == frame) return;
    if (L.asked[b].exchange(frame, std::memory_order_relaxed) == frame) return;
    std::lock_guard<std::mutex> lock(s.asked_mutex);
    s.asked.push_back(BrickKey{l, b, 0});
  }
  void set_slot(int l, int64_t b, int32_t slot) {
    levels[size_t(l)].slot[size_t(b)] = slot;
    if (!copied) return;
    moved.emplace_back(view.level_offset(l) + b, slot);
    if (moved.size() > moved_limit) compact_moved(), moved_limit = std::max(4 * size_t(slots) + 64, 2 * moved.size());
  }
  float* slot_voxels(int32_t slot) {
    if (copied) {
      written.push_back(slot);
      if (written.size() > written_limit) compact_written(), written_limit = 2 * size_t(slots) + 64;
    }
    return pool.get() + int64_t(slot) * view.brick_floats;
  }
  void compact_written() {
    std::sort(written.begin(), written.end());
    written.erase(std::unique(written.begin(), written.end()), written.end());
  }
  // One entry per brick, its last value (a brick evicted and decoded again: its new slot).
  void compact_moved() {
    std::stable_sort(moved.begin(), moved.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    size_t kept = 0;
    for (size_t i = 0; i < moved.size(); ++i)
      if (i + 1 == moved.size() || moved[i + 1].first != moved[i].first) moved[kept++] = moved[i];
    moved.resize(kept);
  }
};

namespace {
struct CachePointFn {
  const BrickCacheView* view;
  const RenderableField* source;
  float operator()(float x, float y, float z) const {
    bool miss = false;
    const float v = view->sample(x, y, z, &miss);
    return miss ? source->point(x, y, z) : v;
  }
};
}  // namespace

CachedField::CachedField(const RenderableField& source, VoxelDecode decode, Int3 dims, BrickCacheSettings settings)
    : source_(&source), decode_(std::move(decode)), dims_(dims), settings_(settings), s_(std::make_unique<State>()) {
  const int B = settings_.brick;
  if (B < 4 || B > 128 || (B & (B - 1))) fail("cache bricks must be a power of two from 4 to 128 cells, got {}", B);
  if (dims.x < 1 || dims.y < 1 || dims.z < 1)
    fail("a brick cache needs dims of at least 1, got {}x{}x{}", dims.x, dims.y, dims.z);
  if (!(settings_.lod_pixels > 0))
    fail("the cache's level-of-detail footprint must be positive, got {}", settings_.lod_pixels);
  if (!decode_) fail("a brick cache needs a decode");
  if (settings_.budget_bytes == 0) settings_.budget_bytes = default_cache_budget();
  State& s = *s_;
  BrickCacheView& v = s.view;
  v.shift = __builtin_ctz(unsigned(B));
  v.sy = B + 1, v.sz = (B + 1) * (B + 1);
  v.brick_floats = int64_t(B + 1) * v.sz;
  v.coarser = settings_.misses == CacheMisses::Coarser;
  v.ask = &State::ask;
  v.cache = &s;
  v.misses = &s.misses;
  const uint64_t brick_bytes = uint64_t(v.brick_floats) * sizeof(float);
  check_cache_budget(settings_.budget_bytes, B);
  s.slots = int32_t(std::min<uint64_t>(settings_.budget_bytes / brick_bytes, uint64_t(INT32_MAX) / uint64_t(v.brick_floats)));
  try {  // not touched here: the OS commits the pages as bricks are written
    s.pool.reset(new float[size_t(s.slots) * size_t(v.brick_floats)]);
  } catch (const std::bad_alloc&) {
    fail("cannot reserve {} for the brick cache: give a smaller cache budget", human_bytes(double(settings_.budget_bytes)));
  }
  v.pool = s.pool.get();
  // The index (per brick of every level: slot and two stamps) lives outside the pool: it must not
  // outgrow it (a resolution far beyond what the budget can show).
  const double level0_bricks = double(ceil_div(dims.x, B)) * double(ceil_div(dims.y, B)) * double(ceil_div(dims.z, B));
  const double index_bytes = level0_bricks * (8.0 / 7.0 * 12.0);
  if (index_bytes > double(settings_.budget_bytes))
    fail("a brick cache of {}x{}x{} voxels needs {} for its index alone, more than its budget of {}: give a "
         "larger budget or a smaller resolution", dims.x, dims.y, dims.z, human_bytes(index_bytes),
         human_bytes(double(settings_.budget_bytes)));
  for (int l = 0;; ++l) {  // down to a level that is one brick
    if (l == BrickCacheView::kMaxLevels) fail("a brick cache of {}x{}x{} voxels needs too many levels", dims.x, dims.y, dims.z);
    Level L;
    L.n = cache_level_dims(dims, l);
    L.nb = Int3{int32_t((L.n.x - 1) / B + 1), int32_t((L.n.y - 1) / B + 1), int32_t((L.n.z - 1) / B + 1)};
    L.slot.assign(size_t(L.bricks()), -1);
    L.used.reset(new std::atomic<uint32_t>[size_t(L.bricks())]());
    L.asked.reset(new std::atomic<uint32_t>[size_t(L.bricks())]());
    if (L.n.x > INT32_MAX || L.n.y > INT32_MAX || L.n.z > INT32_MAX || L.bricks() > INT32_MAX)
      fail("a brick cache of {}x{}x{} voxels has more than 2^31 bricks or voxels a side", dims.x, dims.y, dims.z);
    v.level[l] = CacheLevelView{int32_t(L.n.x),  int32_t(L.n.y),  int32_t(L.n.z),  int32_t(L.nb.x),
                                int32_t(L.nb.y), int32_t(L.nb.z), L.slot.data()};
    v.used[l] = L.used.get();
    s.levels.push_back(std::move(L));
    if (s.levels.back().bricks() == 1) break;
  }
  v.levels = int(s.levels.size());
  s.totals.levels = v.levels;
  s.box = Vec3f{float(dims.x), float(dims.y), float(dims.z)};
  s.totals.budget_bytes = settings_.budget_bytes;
}

CachedField::~CachedField() {
  State& s = *s_;
  if (!s.worker.joinable()) return;
  {
    std::lock_guard<std::mutex> lock(s.work_mu);
    s.stopping = true;
  }
  s.work_cv.notify_all();
  s.worker.join();
}

GpuFieldSource CachedField::gpu_source() const {
  GpuFieldSource g;
  g.dims = dims_;
  g.cache = this;
  return g;
}

float CachedField::point(float x, float y, float z) const { return CachePointFn{&s_->view, source_}(x, y, z); }

bool cache_packets_apply(const RenderParams& p, const BrickCacheView& c) {
  if (p.shade) return false;
  for (int l = 0; l < c.levels; ++l)
    if (c.level[l].nx < 2) return false;
  return true;
}

int64_t CachedField::render_inshader(const InshaderJob& job) const {
  const RenderParams& p = *job.params;
  if (job.ray_packets && job.mode == RenderMode::RayMarch && cache_packets_apply(p, s_->view)) {
    std::atomic<int64_t> samples{0}, next_tile{0};
    parallel_threads([&](int, int) {
      const TileCursor tiles{p.cam.width, p.cam.height, kInshaderTile, 0, 1, &next_tile};
      samples += march_cache_packets(p, s_->view, *source_, tiles, job.pixels);
    });
    return samples.load();
  }
  return run_inshader(job, CachePointFn{&s_->view, source_});
}

void CachedField::query(const float* x, const float* y, const float* z, int64_t n, float* out) const {
  State& s = *s_;
  std::vector<uint8_t> miss(static_cast<size_t>(n));
  parallel_for_claimed(n, 4096, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) {
      bool m = false;
      out[i] = s.view.sample(x[i], y[i], z[i], &m);
      miss[size_t(i)] = m;
    }
  });
  std::vector<int64_t> where;  // the misses, read from the source in one batched query
  for (int64_t i = 0; i < n; ++i)
    if (miss[size_t(i)]) where.push_back(i);
  if (where.empty()) return;
  const size_t m = where.size();
  std::vector<float> px(m), py(m), pz(m), v(m);
  for (size_t k = 0; k < m; ++k) px[k] = x[where[k]], py[k] = y[where[k]], pz[k] = z[where[k]];
  source_->query(px.data(), py.data(), pz.data(), int64_t(m), v.data());
  for (size_t k = 0; k < m; ++k) out[where[k]] = v[k];
}

int32_t CachedField::take_slot() const {
  State& s = *s_;
  if (s.slots_used < s.slots) return s.slots_used++;
  size_t victim = s.resident.size();
  uint32_t oldest = s.view.frame;
  for (size_t r = 0; r < s.resident.size(); ++r) {
    if (s.resident[r].level + 1 == int(s.levels.size())) continue;  // the root stays
    const uint32_t u = s.levels[size_t(s.resident[r].level)].used[s.resident[r].brick].load(std::memory_order_relaxed);
    if (u < oldest) oldest = u, victim = r;
  }
  if (victim == s.resident.size()) return -1;
  const State::Resident gone = s.resident[victim];
  s.set_slot(gone.level, gone.brick, -1);
  s.resident[victim] = s.resident.back();
  s.resident.pop_back();
  s.totals.evicted += 1;
  return gone.slot;
}

bool CachedField::decode_brick(int l, int64_t b) const {
  State& s = *s_;
  Level& L = s.levels[size_t(l)];
  if (L.slot[size_t(b)] >= 0) return true;
  const int32_t slot = take_slot();
  if (slot < 0) return false;
  s.resident.push_back(State::Resident{l, b, slot, s.generation});
  refresh_brick(s.resident.size() - 1);
  s.set_slot(l, b, slot);
  L.used[b].store(s.view.frame, std::memory_order_relaxed);
  return true;
}

void CachedField::brick_voxels(int l, int64_t b, float* out) const {
  const State& s = *s_;
  const Level& L = s.levels[size_t(l)];
  // The brick's voxels with its far faces, clamped to the level (the lookup never reads past them).
  const int B = settings_.brick, side = B + 1;
  const auto [bx, by, bz] = L.brick_coords(b);
  std::vector<int64_t> index(size_t(s.view.brick_floats));
  for (int k = 0; k < side; ++k)
    for (int j = 0; j < side; ++j)
      for (int i = 0; i < side; ++i) {
        const int64_t gx = std::min<int64_t>(bx * B + i, L.n.x - 1), gy = std::min<int64_t>(by * B + j, L.n.y - 1),
                      gz = std::min<int64_t>(bz * B + k, L.n.z - 1);
        index[size_t(i + side * (j + int64_t(side) * k))] = gx + L.n.x * (gy + int64_t(L.n.y) * gz);
      }
  std::lock_guard<std::mutex> lock(s_->decode_mu);
  decode_(L.n, index.data(), int64_t(index.size()), out);
}

void CachedField::refresh_brick(size_t r) const {
  State& s = *s_;
  State::Resident& res = s.resident[r];
  brick_voxels(res.level, res.brick, s.slot_voxels(res.slot));
  res.generation = s.generation;
  s.totals.decoded += 1;
  s.version += 1;
}

void CachedField::replace_source(const RenderableField& source, bool model_changed, VoxelDecode decode) const {
  source_ = &source;
  if (decode) {
    std::lock_guard<std::mutex> lock(s_->decode_mu);
    decode_ = std::move(decode);
  }
  if (model_changed) s_->generation += 1;
}

uint64_t CachedField::content_version() const { return s_->version; }

float CachedField::brick_distance(int level, int64_t brick) const {
  const Level& L = s_->levels[size_t(level)];
  const int64_t B = settings_.brick;
  const auto [bx, by, bz] = L.brick_coords(brick);
  const Vec3f box = s_->box;
  const Vec3f c{(float(bx * B) + 0.5f * float(B)) / float(L.n.x) * box.x,
                (float(by * B) + 0.5f * float(B)) / float(L.n.y) * box.y,
                (float(bz * B) + 0.5f * float(B)) / float(L.n.z) * box.z};
  if (s_->focus) {  // under the cursor first: the distance from its ray (behind the eye: from the eye)
    const auto& [o, d] = *s_->focus;
    const Vec3f rel = c - o;
    const float along = dot(rel, d);
    return along > 0 ? length(rel - d * along) : length(rel);
  }
  return length(c - s_->lod_cam.eye);
}

void CachedField::set_focus(std::optional<std::pair<Vec3f, Vec3f>> origin_and_direction) const {
  if (origin_and_direction) origin_and_direction->second = normalize(origin_and_direction->second);
  s_->focus = origin_and_direction;
}

void CachedField::decode_asked(double seconds, const std::function<void(int64_t, int64_t)>& progress) const {
  State& s = *s_;
  const auto t0 = std::chrono::steady_clock::now();
  const std::vector<BrickKey> todo = take_requests();
  size_t done = 0;
  bool full = false;  // every slot holds a brick the last frame read: the rest keep reading the source
  for (; done < todo.size(); ++done) {  // what is left is asked for again by the next frames that need it
    if (seconds >= 0 && done > 0 && seconds_since(t0) >= seconds) break;
    if (!decode_brick(todo[done].level, todo[done].brick)) {
      full = true;
      break;
    }
    if (progress) progress(int64_t(done + 1), int64_t(todo.size()));
  }
  s.totals.requested = full ? 0 : int64_t(todo.size() - done);
  const std::vector<size_t> stale = stale_bricks();
  for (const size_t r : stale) {  // in the time left; at least one brick a frame, new or refreshed
    if (seconds >= 0 && (done > 0 || r != stale.front()) && seconds_since(t0) >= seconds) break;
    refresh_brick(r);
  }
  s.totals.decode_seconds += seconds_since(t0);
}

// Stale bricks in the order they are refreshed: those the last frame read first, then the oldest (the
// earliest model's), then the nearest. While a model trains every brick turns stale each step; oldest
// first sweeps the whole view (nearest first would refresh the same near bricks step after step).
std::vector<size_t> CachedField::stale_bricks() const {
  const State& s = *s_;
  struct Stale {
    bool unread;    // not read by the last frame
    uint32_t age;   // models since it was decoded
    float distance;
    size_t r;
  };
  std::vector<Stale> stale;
  for (size_t r = 0; r < s.resident.size(); ++r) {
    const State::Resident& res = s.resident[r];
    if (res.generation == s.generation) continue;
    const Level& L = s.levels[size_t(res.level)];
    const bool read = L.used[res.brick].load(std::memory_order_relaxed) == s.view.frame;
    stale.push_back(Stale{!read, s.generation - res.generation, brick_distance(res.level, res.brick), r});
  }
  std::sort(stale.begin(), stale.end(), [](const Stale& a, const Stale& b) {
    if (a.unread != b.unread) return b.unread;
    if (a.age != b.age) return a.age > b.age;
    return a.distance < b.distance;
  });
  std::vector<size_t> out;
  for (const Stale& st : stale) out.push_back(st.r);
  return out;
}

// The bricks asked for since the last frame, nearest the camera (or the cursor's ray) first.
std::vector<BrickKey> CachedField::take_requests() const {
  State& s = *s_;
  std::vector<BrickKey> todo;
  {
    std::lock_guard<std::mutex> lock(s.asked_mutex);
    todo.swap(s.asked);
  }
  for (BrickKey& k : todo) k.distance = brick_distance(k.level, k.brick);
  std::sort(todo.begin(), todo.end(), [](const BrickKey& a, const BrickKey& b) { return a.distance < b.distance; });
  return todo;
}

void CachedField::hand_over_requests() const {
  State& s = *s_;
  // New bricks only as many as the pool can take without evicting one the last frame read (the rest
  // are asked for again), then the stale bricks; the job list is reversed: the thread takes the back.
  int64_t room = s.slots - s.slots_used;
  for (const State::Resident& r : s.resident)
    room += r.level + 1 != int(s.levels.size()) &&
            s.levels[size_t(r.level)].used[r.brick].load(std::memory_order_relaxed) != s.view.frame;
  std::vector<State::Job> jobs;
  for (const BrickKey& k : take_requests())
    if (s.levels[size_t(k.level)].slot[size_t(k.brick)] < 0 && int64_t(jobs.size()) < room)
      jobs.push_back(State::Job{k.level, k.brick, s.generation});
  for (const size_t r : stale_bricks()) jobs.push_back(State::Job{s.resident[r].level, s.resident[r].brick, s.generation});
  std::reverse(jobs.begin(), jobs.end());
  {
    std::lock_guard<std::mutex> lock(s.work_mu);
    s.jobs = std::move(jobs);
  }
  s.work_cv.notify_one();
}

void CachedField::install_decoded() const {
  State& s = *s_;
  std::vector<State::Decoded> done;
  {
    std::lock_guard<std::mutex> lock(s.work_mu);
    if (!s.error.empty()) {  // reported once; the bricks it left are asked for again
      const std::string error = std::move(s.error);
      s.error.clear();
      fail("decoding the brick cache: {}", error);
    }
    done.swap(s.decoded);
  }
  for (State::Decoded& d : done) {
    Level& L = s.levels[size_t(d.job.level)];
    int32_t slot = L.slot[size_t(d.job.brick)];
    if (slot >= 0) {  // resident: a stale brick's refresh, unless the frame decoded it meanwhile
      const auto it = std::find_if(s.resident.begin(), s.resident.end(),
                                   [&](const State::Resident& r) { return r.slot == slot; });
      if (it->generation == s.generation) continue;
      it->generation = d.job.generation;
    } else {
      slot = take_slot();
      if (slot < 0) continue;  // every resident brick still in use: asked for again by the frames
      s.resident.push_back(State::Resident{d.job.level, d.job.brick, slot, d.job.generation});
      s.set_slot(d.job.level, d.job.brick, slot);
      L.used[d.job.brick].store(s.view.frame, std::memory_order_relaxed);
    }
    std::copy(d.voxels.begin(), d.voxels.end(), s.slot_voxels(slot));
    s.totals.decoded += 1;
    s.version += 1;
  }
}

void CachedField::decoding_thread() const {
  omp_set_num_threads(1);  // one core decodes; the frames keep the others
  State& s = *s_;
  std::unique_lock<std::mutex> lock(s.work_mu);
  for (;;) {
    s.work_cv.wait(lock, [&] { return s.stopping || !s.jobs.empty(); });
    if (s.stopping) return;
    State::Decoded d{s.jobs.back(), {}};
    s.jobs.pop_back();
    s.in_flight = true;
    lock.unlock();
    std::string error;
    try {
      d.voxels.resize(size_t(s.view.brick_floats));
      brick_voxels(d.job.level, d.job.brick, d.voxels.data());
    } catch (const std::exception& e) {
      error = e.what();
    }
    lock.lock();
    s.in_flight = false;
    if (!error.empty()) {
      if (s.error.empty()) s.error = error;
    } else {
      s.decoded.push_back(std::move(d));
    }
    s.done_cv.notify_all();
  }
}

void CachedField::set_asynchronous(bool on) const {
  State& s = *s_;
  if (on == s.async) return;
  s.async = on;
  if (on) {
    if (!s.worker.joinable()) s.worker = std::thread([this] { decoding_thread(); });
    return;
  }
  std::unique_lock<std::mutex> lock(s.work_mu);
  s.jobs.clear();  // the frames ask for them again
  s.done_cv.wait(lock, [&] { return !s.in_flight; });
}

bool CachedField::wait_for_bricks(double seconds) const {
  State& s = *s_;
  std::unique_lock<std::mutex> lock(s.work_mu);
  s.done_cv.wait_for(lock, std::chrono::duration<double>(seconds),
                     [&] { return !s.decoded.empty() || (s.jobs.empty() && !s.in_flight); });
  return !s.decoded.empty();
}

// Levels of detail for a new view (BrickCacheView::level_at): a level-0 voxel's width in pixels at unit
// distance from the eye, over lod_pixels.
void CachedField::update_levels(const RenderParams& p) const {
  State& s = *s_;
  const CameraFrame& c = p.cam;
  s.lod_cam = c;
  s.box = p.box;
  BrickCacheView& v = s.view;
  v.eye[0] = c.eye.x, v.eye[1] = c.eye.y, v.eye[2] = c.eye.z;
  v.box[0] = p.box.x, v.box[1] = p.box.y, v.box[2] = p.box.z;
  v.lod_scale = cache_lod_scale(c, p.box, dims_, settings_.lod_pixels);
  v.level0_only = v.box_reads_level0();
}

void CachedField::begin_frame(const RenderParams& p) const {
  State& s = *s_;
  const auto same = [](Vec3f a, Vec3f b) { return a.x == b.x && a.y == b.y && a.z == b.z; };
  if (!same(p.cam.eye, s.lod_cam.eye) || !same(p.cam.dv, s.lod_cam.dv) || p.cam.height != s.lod_cam.height)
    update_levels(p);
  // The root brick first: with it, a Coarser cache answers every sample from the first frame on.
  if (s.view.coarser && s.levels.back().slot[0] < 0) decode_brick(int(s.levels.size()) - 1, 0);
  install_decoded();  // the decoding thread's, also when it was just turned off
  if (s.async) hand_over_requests();
  else decode_asked(settings_.decode_seconds);
  s.misses = 0;
  s.view.frame += 1;
}

void CachedField::decode_pending(const std::function<void(int64_t, int64_t)>& progress) const {
  State& s = *s_;
  {  // the decoding thread's jobs are decoded here, with every thread
    std::unique_lock<std::mutex> lock(s.work_mu);
    {
      std::lock_guard<std::mutex> asked(s.asked_mutex);
      for (const State::Job& j : s.jobs)
        if (s.levels[size_t(j.level)].slot[size_t(j.brick)] < 0) s.asked.push_back(BrickKey{j.level, j.brick, 0});
    }
    s.jobs.clear();
    s.done_cv.wait(lock, [&] { return !s.in_flight; });
  }
  install_decoded();
  decode_asked(-1, progress);
}

BrickCacheStats CachedField::stats() const {
  const State& s = *s_;
  BrickCacheStats st = s.totals;
  st.resident = int64_t(s.resident.size());
  st.pool_bytes = uint64_t(s.slots_used) * uint64_t(s.view.brick_floats) * sizeof(float);
  st.misses = s.misses.load();
  if (s.async) {
    std::lock_guard<std::mutex> lock(s_->work_mu);
    st.requested = int64_t(s.jobs.size() + s.decoded.size()) + int64_t(s.in_flight);
  }
  for (const State::Resident& r : s.resident) st.stale += r.generation != s.generation;
  return st;
}

const BrickCacheView& CachedField::view() const { return s_->view; }

int32_t CachedField::pool_slots() const { return s_->slots; }

BrickCacheChanges CachedField::take_changes(bool from_scratch) const {
  State& s = *s_;
  BrickCacheChanges out;
  if (from_scratch) {
    s.copied = true;
    s.written.clear();
    s.moved.clear();
    for (const State::Resident& r : s.resident) {
      out.slots.push_back(r.slot);
      out.entries.emplace_back(s.view.level_offset(r.level) + r.brick, r.slot);
    }
    std::sort(out.slots.begin(), out.slots.end());
    return out;
  }
  s.compact_written();
  s.compact_moved();
  out.slots.swap(s.written);
  out.entries.swap(s.moved);
  return out;
}

int64_t CachedField::changes_pending() const { return int64_t(s_->written.size() + s_->moved.size()); }

void CachedField::take_reads(const uint32_t* slot_read, const int32_t* requests, int64_t n, int64_t misses) const {
  State& s = *s_;
  for (const State::Resident& r : s.resident) {
    std::atomic<uint32_t>& used = s.levels[size_t(r.level)].used[r.brick];
    if (slot_read[r.slot] > used.load(std::memory_order_relaxed)) used.store(slot_read[r.slot], std::memory_order_relaxed);
  }
  for (int64_t i = 0; i < n; ++i) {
    const int l = requests[2 * i];
    const int64_t b = requests[2 * i + 1];
    if (l >= 0 && l < int(s.levels.size()) && b >= 0 && b < s.levels[size_t(l)].bricks()) State::ask(&s, l, b);
  }
  s.misses += misses;
}

}  // namespace vnr
