#pragma once
// Frame rendering: the three integrators of integrators.h in two execution strategies.
//  - in-shader: every pixel's ray runs its whole loop and evaluates the field one point at a time
//    (inshader_loop.h, with the point function the Field hands over), the paper's baseline;
//  - sample streaming: wavefront ray queues; each iteration a coordinate stage emits up to K samples
//    per live ray, one batched Field::query evaluates them all, a shading stage consumes them, and
//    finished rays are compacted away (stream_stages.h; paper Figs. "Ray marching algorithms using sample-streaming"
//    and "path tracing algorithm using sample-streaming"). Shadow rays are a second streaming pass.
// Both strategies, on both backends, call the same per-ray functions in the same order, so for the same seed they give
// the same image whenever the two field evaluations agree bit for bit (they do for the grid).
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>
#include "vnr/device.h"
#include "vnr/render_options.h"
#include "vnr/render/camera.h"
#include "vnr/render/field.h"
#include "vnr/render/image.h"
#include "vnr/render/integrators.h"
#include "vnr/render/macrocell.h"
#include "vnr/scene.h"
#include "vnr/render/transfer_function.h"

namespace vnr {

// Progressive accumulation: acc becomes the mean of frames 0..index (acc held the mean of 0..index-1).
// With m2 (one value per pixel, reset at index 0), Welford's sum of squared deviations of each pixel's
// (r + g + b) / 3 over the frames is kept as well, for accumulated_noise.
void accumulate_frame(Image& acc, const Image& frame, int index, std::vector<float>* m2 = nullptr);
// A pixel of the running mean after a frame of weight w = 1 / (frames so far): accumulate_frame's
// arithmetic, also the GPU's (render_mean_rgba8).
VNR_HD inline Vec4f running_mean(Vec4f a, Vec4f b, float w) {
  return Vec4f{a.x + (b.x - a.x) * w, a.y + (b.y - a.y) * w, a.z + (b.z - a.z) * w, a.w + (b.w - a.w) * w};
}
// The RMS over pixels of the standard error of the accumulated mean after `frames` frames (infinite
// before two): how far, on average, the image still is from the converged one in [0, 1] units.
double accumulated_noise(const std::vector<float>& m2, int frames);

// Validates the options and fills the per-ray parameters (pointers into tf and mc: host memory) for a
// field of `dims` voxels in a box of world size `box`, seen from cam.
RenderParams make_render_params(Int3 dims, Vec3f box, const MacroCells& mc, const TransferFunction& tf,
                                const Camera& cam, const RenderOptions& opt);
// A new view: the camera frame for the image size of opt, and the light flip of B.8 (the original
// turns the light to the viewer's side when it points away from the camera).
void set_render_camera(RenderParams& p, const Camera& cam, const RenderOptions& opt);

// A renderer on some backend: the CPU's CpuRenderer below, or the GPU's (render_cuda/gpu_renderer.h).
class FrameRenderer {
public:
  virtual ~FrameRenderer() = default;
  // Renders frame number `frame` (its jitter and random numbers) into img (overwritten).
  virtual void render_frame(uint32_t frame, Image& img, RenderStats* stats = nullptr) = 0;
  // The same frame left where it was rendered (a GPU frame stays in GPU memory, as a viewer displays
  // it): what benchmarks time.
  virtual void render_frame_resident(uint32_t frame, RenderStats* stats = nullptr);
  // A new view for the next frames (e.g. an orbit); the light flip of B.8 follows the camera.
  virtual void set_camera(const Camera& cam) = 0;
  // The field's network has new parameters (same configuration) and mc new value ranges, as after more
  // training steps on the GPU: the renderer takes both in place, the parameters from device_half (a
  // trainer's half parameters in GPU memory). False when it cannot (the caller builds a new renderer; the
  // CPU renderer's evaluators are rebuilt that way, at little cost).
  virtual bool refresh_network(const MacroCells& mc, const void* device_half) {
    (void)mc, (void)device_half;
    return false;
  }
  virtual Device device() const = 0;
  // Renders `frames` frames (0, 1, ...) and returns their average (progressive accumulation).
  Image render(int frames, RenderStats* stats = nullptr);
  // Renders frame number `frame` and folds it into the mean of frames 0..frame (frame 0, or the first
  // call, starts it; accumulate_frame's arithmetic), then writes the mean as to_rgba8's bytes into rgba:
  // what a viewer shows. The GPU keeps the mean in its memory and copies back only the 8-bit image.
  virtual void render_mean_rgba8(uint32_t frame, std::vector<uint8_t>& rgba);

private:
  Image resident_, frame_, mean_;
};

struct CpuStreamBackend;  // renderer.cpp: the streaming buffers

class CpuRenderer final : public FrameRenderer {
public:
  // field, macro-cells and tf must outlive the renderer; box = world size of the volume box.
  CpuRenderer(const Field& field, Vec3f box, const MacroCells& mc, const TransferFunction& tf, const Camera& cam,
              const RenderOptions& opt);
  ~CpuRenderer() override;
  void render_frame(uint32_t frame, Image& img, RenderStats* stats = nullptr) override;
  void set_camera(const Camera& cam) override;
  Device device() const override { return Device::Cpu; }
  const RenderParams& params() const { return params_; }

private:
  const Field& field_;
  RenderOptions opt_;
  RenderParams params_;
  std::unique_ptr<CpuStreamBackend> stream_;  // streaming buffers, kept between frames
};

}  // namespace vnr
