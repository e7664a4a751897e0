#pragma once
// What a frame is rendered with and what it cost: the integrator (mode), the execution strategy, the
// per-frame options, macro-cells, and the brick cache's settings and statistics (docs/RENDERING.md).
// RenderSettings (vnr/render_settings.h) is the request front ends fill; these are the Renderer's own.
#include <cstdint>
#include <string>
#include "vnr/math.h"
#include "vnr/scene.h"

namespace vnr {

enum class RenderMode { RayMarch, Shadow, PathTrace };
enum class RenderStrategy { InShader, Streaming };
RenderMode parse_render_mode(const std::string& s);
RenderStrategy parse_render_strategy(const std::string& s);
const char* render_mode_name(RenderMode m);
const char* render_strategy_name(RenderStrategy s);
// The faster strategy for a field kind ("grid", "network" or "cache": a grid of bricks), device and mode, as measured on bonsai
// (docs/benchmarks.md: CPU ray marching and path tracing of a grid in-shader (packets), its shadows
// streaming, a network streaming; GPU grids in-shader (17-20x), GPU networks in-shader but shadows).
RenderStrategy fastest_render_strategy(const std::string& field_kind, bool gpu, RenderMode mode);

// Samples per live ray per streaming iteration (docs/semantics.md B.7); `vnr bench render --tune-k`
// finds the best K for a machine.
constexpr int kDefaultSamplesPerIteration = 8;

struct RenderOptions {
  RenderMode mode = RenderMode::RayMarch;
  RenderStrategy strategy = RenderStrategy::Streaming;
  int width = 768, height = 768;
  float step = 1;             // s1, world units (voxels)
  float step_max = 0;         // s2; 0 = 16 * step (docs/semantics.md B.7 default)
  float density_scale = 1;    // path tracing
  bool shade = false;         // gradient shading for ray marching
  uint32_t seed = 0;
  int samples_per_iteration = kDefaultSamplesPerIteration;  // K
  // In-shader ray marching of a grid runs rays in SIMD packets (fields/grid_packets.h; same image bit for
  // bit); false runs the portable per-ray loop, the reference the packets are tested against.
  bool ray_packets = true;
  Vec3f background{0, 0, 0};
  DirectionalLight light;
};

struct RenderStats {
  int frames = 0;
  int64_t rays = 0;           // primary rays (pixels x frames)
  int64_t field_samples = 0;  // field evaluations (including gradient neighbours)
  int64_t iterations = 0;     // streaming iterations
  int64_t host_syncs = 0;     // GPU: times the host waited for the device (streaming: one per iteration)
  double seconds = 0;
};

enum class MacroCellMode { Grid, Online, Off };
MacroCellMode parse_macrocell_mode(const std::string& s);
const char* macrocell_mode_name(MacroCellMode m);

enum class CacheMisses {
  Exact,   // a sample whose brick is not decoded yet reads the model's field (vnr render: exact frames)
  Coarser  // it reads the nearest decoded coarser level (the viewer: fast frames that sharpen)
};

struct BrickCacheSettings {
  uint64_t budget_bytes = 0;     // pool of decoded bricks; 0 = default_cache_budget()
  int brick = 32;                // cells per brick side (a power of two, 4..128)
  float lod_pixels = 1;          // level l where a level-l voxel covers at most this many pixels
  double decode_seconds = 0.05;  // decoding per frame (begin_frame); at least one brick a frame
  CacheMisses misses = CacheMisses::Exact;
  Int3 dims{0, 0, 0};            // level 0's voxels (Renderer: 0 = the model's dims; any size)
};

// Fails with the sizes unless `budget_bytes` holds one brick of `brick`^3 cells ((brick + 1)^3 floats).
void check_cache_budget(uint64_t budget_bytes, int brick);
// A quarter of the memory available, at most 4 GiB, at least 64 MiB.
uint64_t default_cache_budget();
// "512MiB", "2GiB", "100M", plain bytes; 0 or "auto" = default_cache_budget(). Fails on anything else.
uint64_t parse_cache_budget(const std::string& text);

struct BrickCacheStats {
  int64_t resident = 0, decoded = 0, evicted = 0;  // bricks in the pool now, decoded and evicted so far
  int64_t requested = 0;  // bricks asked for and left for later frames (0 when the budget is full),
                          // asynchronous: waiting for the decoding thread or decoded and not installed yet
  int64_t misses = 0;  // samples of the current frame (since begin_frame) that read the source
  int64_t stale = 0;   // resident bricks decoded from an earlier model (replace_source)
  uint64_t pool_bytes = 0, budget_bytes = 0;
  int levels = 0;
  double decode_seconds = 0;  // in begin_frame, all frames
};

}  // namespace vnr
