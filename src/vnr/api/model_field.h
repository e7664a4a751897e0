#pragma once
// The field a renderer draws for a Model: its network, or a multi-brick model's blended bricks.
#include <algorithm>
#include <memory>
#include "vnr/fields/brick_cache.h"
#include "vnr/fields/bricked_field.h"
#include "vnr/fields/fields.h"
#include "vnr/error.h"
#include "vnr/units.h"
#include "vnr/nn/mlp_layout.h"
#include "vnr/render_options.h"
#include "vnr/train/bricks.h"
#include "vnr/train/decoder.h"
#include "vnr/train/model_form.h"

namespace vnr {

// Why the model cannot render on the GPU ("" when it can): a network the GPU kernels do not support, or
// a multi-brick model whose decode does not fit.
inline std::string gpu_render_reason(const Model& model) { return form_of(model).gpu_render_reason(model); }

// Whether the in-shader strategy can draw the model's network on `device`: the GPU's in-shader MLP runs
// 16-wide tiles only (a CutlassMLP's may not be); a multi-brick model is drawn from its decode there, a grid.
inline bool inshader_can_draw(const Model& model, Device device) {
  return device != Device::Cuda || model.bricks || mlp_in_16_wide_tiles(model.net->mlp());
}

// The faster strategy for a field of `kind` on `device` (fastest_render_strategy), streaming where the
// field is a model's network in-shader cannot draw (model: null for a volume).
inline RenderStrategy automatic_strategy_for(const Model* model, const std::string& kind, Device device,
                                             RenderMode mode) {
  if (model && kind == "network" && !inshader_can_draw(*model, device)) return RenderStrategy::Streaming;
  return fastest_render_strategy(kind, device == Device::Cuda, mode);
}

// A multi-brick model drawn on the GPU from its decode: decoded once at dims on the GPU (the bricks
// blended as on the CPU; residuals where they apply: Decoder), then ray marched as a grid, trilinear
// between voxel centres (where the CPU's BrickedField queries the networks; docs/MODEL_FORMAT.md states
// the difference).
class DecodedModelField final : public RenderableField {
public:
  DecodedModelField(const Model& model, Int3 dims) : grid_(GridView{}) {
    cuda::require_device();
    decoded_.dims = dims;
    decoded_.data.resize(dims.count());
    Decoder(model, Device::Cuda).slices(dims, 0, dims.z, decoded_.data.data());
    grid_ = GridField(view_of(decoded_));
  }
  Int3 dims() const override { return grid_.dims(); }
  const char* kind() const override { return "network"; }
  void query(const float* x, const float* y, const float* z, int64_t n, float* out) const override {
    grid_.query(x, y, z, n, out);
  }
  int64_t render_inshader(const InshaderJob& job) const override { return grid_.render_inshader(job); }
  GpuFieldSource gpu_source() const override { return grid_.gpu_source(); }
  float point(float x, float y, float z) const override { return grid_.point(x, y, z); }

private:
  Volume decoded_;
  GridField grid_;
};

// The device of the field behind a model's brick cache (what the host cache's misses read) on any
// renderer's device: the CPU (the GPU's copy of the cache reads coarser levels instead, so a multi-brick
// model is not decoded whole for it).
constexpr Device kCacheSourceDevice = Device::Cpu;

// The field of a model for a renderer on `device`: its network, or a multi-brick model's blended bricks
// (on the GPU: their decode).
inline std::unique_ptr<RenderableField> make_model_field(const Model& model, Device device) {
  struct Maker final : ModelFieldMaker {
    Device device;
    std::unique_ptr<RenderableField> field;
    void network(const Model& m) override { field = std::make_unique<NetworkField>(*m.net, m.dims); }
    void bricks(const Model& m, BrickedModel& b) override {
      if (device == Device::Cuda) {
        if (const std::string why = gpu_render_reason(m); !why.empty()) fail("{}", why);
        field = std::make_unique<DecodedModelField>(m, m.dims);
        return;
      }
      std::vector<const Network*> nets;
      for (auto& brick : b.bricks) nets.push_back(brick ? brick->net.get() : nullptr);
      field = std::make_unique<BrickedField>(std::move(nets), *b.layout);
    }
  } maker;
  maker.device = device;
  form_of(model).make_field(model, maker);
  return std::move(maker.field);
}

// What a brick cache decodes with: a Decoder of the model (residuals at the model's dims, multi-brick
// models blended), on the CPU or the GPU. A GPU decoder holds its own copy of the parameters: after
// training it takes the new ones (Decoder::reload_device_params) or is replaced
// (CachedField::replace_source).
inline VoxelDecode cache_decode(std::shared_ptr<Decoder> decoder) {
  return [decoder](Int3 dims, const int64_t* index, int64_t n, float* out) { decoder->voxels(dims, index, n, out); };
}

// A brick cache's settings for a renderer on `device`. The GPU renders from a copy of the pool in its
// memory (render_cuda/cache_copy.cuh): the budget is at most a quarter of the GPU's free memory, and the
// copy's misses read the nearest decoded coarser level (the host cache decodes the root first).
inline BrickCacheSettings cache_settings_for(BrickCacheSettings s, Device device) {
  if (device != Device::Cuda) return s;
  s.misses = CacheMisses::Coarser;
  const uint64_t budget = s.budget_bytes ? s.budget_bytes : default_cache_budget();
  s.budget_bytes = std::min(budget, cuda::free_memory_bytes() / 4);
  return s;
}

// The brick cache of a model in front of its field `source` (which must outlive it), decoded by
// `decoder`; level 0 at settings.dims, or the model's dims when 0.
inline std::unique_ptr<CachedField> make_model_cache(const Model& model, const RenderableField& source,
                                                     const BrickCacheSettings& settings,
                                                     std::shared_ptr<Decoder> decoder) {
  return std::make_unique<CachedField>(source, cache_decode(std::move(decoder)),
                                       settings.dims.count() > 0 ? settings.dims : model.dims, settings);
}

}  // namespace vnr
