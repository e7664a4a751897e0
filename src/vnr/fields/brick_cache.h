#pragma once
// A cache of decoded bricks in front of a model's field (docs/RENDERING.md "Brick cache"): the model
// decoded at several levels of detail (level l = the model's dims halved l times), each level cut into
// bricks of B^3 cells stored with their far faces ((B+1)^3 voxels), so a trilinear lookup never leaves
// its brick. A sample reads the level its distance to the camera asks for (a level-l voxel covers at
// most `lod_pixels` pixels), from a bounded pool of bricks (least recently used evicted); a brick not
// decoded yet is requested, and the sample reads the model's field directly (exact) or the nearest
// decoded coarser level (interactive: no network query at all once the root brick is in). Between
// frames (Field::begin_frame) the requested bricks are decoded nearest first within a time budget, or,
// asynchronous, by a decoding thread of the cache's own while frames render, so no frame waits for the
// whole cache. At level 0 a warm cache reads exactly what a GridField over the
// model's decode reads (the same voxels, the same cell-centred trilinear arithmetic).
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>
#include "vnr/render_options.h"
#include "vnr/render/brick_cache_view.h"
#include "vnr/render/camera.h"
#include "vnr/fields/fields.h"

namespace vnr {

// The decode a cache fills its bricks with: n voxels of a grid of `dims` voxels given by index
// (x + dims.x * (y + dims.y * z)), normalised values out (train's Decoder::voxels: what a whole decode
// at those dims gives them, residuals included where they apply).
using VoxelDecode = std::function<void(Int3 dims, const int64_t* voxel_index, int64_t n, float* out)>;

// The levels of detail as a view asks for them (CachedField's rule): a sample at distance d from the eye
// covers d * lod_scale level-0 voxels per lod_pixels pixels, of a cache of `dims` voxels over the box
// [0, box] seen through camera frame c.
float cache_lod_scale(const CameraFrame& c, Vec3f box, Int3 dims, float lod_pixels);
// Level l's voxels: dims halved l times, rounded up, at least one.
Int3 cache_level_dims(Int3 dims, int level);


struct BrickKey;  // brick_cache.cpp: a brick of a level and its decoding priority

class CachedField final : public RenderableField, public BrickCacheCopySource {
public:
  // source (the model's field) and decode must outlive the cache; dims = the level-0 grid (usually the
  // model's dims, any size: only the bricks a view needs are decoded).
  CachedField(const RenderableField& source, VoxelDecode decode, Int3 dims, BrickCacheSettings settings = {});
  ~CachedField() override;
  Int3 dims() const override { return dims_; }
  const char* kind() const override { return "cache"; }
  void query(const float* x, const float* y, const float* z, int64_t n, float* out) const override;
  int64_t render_inshader(const InshaderJob& job) const override;
  void begin_frame(const RenderParams& p) const override;
  // The GPU renderer keeps a copy of the cache in GPU memory (BrickCacheCopySource below).
  GpuFieldSource gpu_source() const override;
  float point(float x, float y, float z) const override;

  // Decodes every brick requested so far, however long it takes (tests, benchmarks' warm cache);
  // progress(done, total) after each brick.
  void decode_pending(const std::function<void(int64_t, int64_t)>& progress = {}) const;
  // Misses read `source` from now on. With `model_changed` (training in the loop) every decoded brick
  // is stale: still read, and decoded again in the frame budget new bricks leave, the bricks the last
  // frame read first, the oldest first, then the nearest; with `decode`, by that decode from now on (one that holds its own
  // copy of the model, as a GPU decoder does). The decoding thread must be off (set_asynchronous).
  void replace_source(const RenderableField& source, bool model_changed, VoxelDecode decode = {}) const;
  // The ray under the user's cursor (world units; none: no cursor): bricks near it are decoded first.
  void set_focus(std::optional<std::pair<Vec3f, Vec3f>> origin_and_direction) const;
  // Grows whenever a brick is decoded: an image accumulated over frames restarts when it changes.
  uint64_t content_version() const;
  BrickCacheStats stats() const;
  const BrickCacheSettings& settings() const { return settings_; }
  void set_decode_seconds(double seconds) const { settings_.decode_seconds = seconds; }  // per frame from now on
  // Asynchronous: begin_frame installs the bricks the decoding thread finished and hands it the frame's
  // requests (nearest first, then stale bricks) instead of decoding them itself; the thread decodes
  // with one CPU thread while frames render. The model the decode reads must not change meanwhile:
  // set_asynchronous(false) first (it waits for the brick in flight). Off by default.
  void set_asynchronous(bool on) const;
  // Asynchronous: waits up to `seconds` for the decoding thread to finish a brick; false when none came
  // (it has nothing to do, or the time ran out).
  bool wait_for_bricks(double seconds) const;
  const BrickCacheView& view() const override;  // what lookups read (render/brick_cache_view.h)
  // A copy of the cache where frames render (render/brick_cache_view.h, BrickCacheCopySource): from the
  // first take_changes on, the cache records the slots it writes and the page-table entries it sets.
  int32_t pool_slots() const override;
  BrickCacheChanges take_changes(bool from_scratch) const override;
  int64_t changes_pending() const;  // slots and entries recorded for a copy and not yet taken
  void take_reads(const uint32_t* slot_read, const int32_t* requests, int64_t n, int64_t misses) const override;

  struct State;  // brick_cache.cpp: levels, page tables, pool, requests

private:
  // Decodes brick b of level l into a pool slot (evicting the least recently used brick not read by
  // the last frame when the budget is full); false when every resident brick is still in use.
  bool decode_brick(int l, int64_t b) const;
  // Decodes resident brick r (again, when stale).
  void refresh_brick(size_t r) const;
  // The voxels of brick b of level l with its far faces ((B+1)^3, x fastest) from decode_.
  void brick_voxels(int l, int64_t b, float* out) const;
  // A pool slot for a new brick, evicting the least recently read brick the last frame did not read
  // when the pool is full; -1 when every resident brick is still in use.
  int32_t take_slot() const;
  // Asynchronous: moves the bricks the decoding thread finished into the pool, and gives it the
  // requests of the frame just rendered.
  void install_decoded() const;
  void hand_over_requests() const;
  void decoding_thread() const;
  // The bricks asked for since the last frame, nearest first; the stale resident bricks (decoded from
  // an earlier model), those the last frame read first, then the nearest.
  std::vector<BrickKey> take_requests() const;
  std::vector<size_t> stale_bricks() const;
  // Decodes the bricks asked for, nearest the camera first, until `seconds` have passed (< 0: all).
  void decode_asked(double seconds, const std::function<void(int64_t, int64_t)>& progress = {}) const;
  void update_levels(const RenderParams& p) const;
  // Decoding order: its centre's distance from the cursor's ray, else from the last view's eye (world units).
  float brick_distance(int level, int64_t brick) const;

  mutable const RenderableField* source_;  // replace_source changes it
  mutable VoxelDecode decode_;  // replace_source can change it
  Int3 dims_;
  mutable BrickCacheSettings settings_;  // decode_seconds can change between frames
  std::unique_ptr<State> s_;
};

}  // namespace vnr
