#pragma once
// The multi-brick machinery behind vnr/bricks.h: blending, region decodes on the CPU and the GPU, merged
// macro-cells.
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>
#include "vnr/bricks.h"
#include "vnr/core/brick_box.h"
#include "vnr/json.h"
#include "vnr/cuda/cuda.h"
#include "vnr/train/model_io.h"
#include "vnr/train/session.h"
#include "vnr/volume/stream.h"

namespace vnr {

BrickLayout layout_of(const BrickPlan& plan);

// The bricks' networks on the GPU for the blends above: each copied on first use, the least recently
// used released when more would not fit a quarter of the GPU's free memory (at least one stays).
class BrickGpuNetworks {
public:
  explicit BrickGpuNetworks(const BrickedModel& m, cuda::MlpPath mlp = cuda::MlpPath::Auto);
  ~BrickGpuNetworks();
  void infer(int b, const float* xyz, int64_t n, float* out);
  BrickInfer fn() {
    return [this](int b, const float* xyz, int64_t n, float* out) { infer(b, xyz, n, out); };
  }
  size_t capacity() const { return capacity_; }  // networks held at once

private:
  const BrickedModel& m_;
  cuda::MlpPath mlp_;
  std::vector<std::unique_ptr<cuda::GpuNetwork>> nets_;
  std::vector<uint64_t> last_use_;
  uint64_t clock_ = 0;
  size_t capacity_ = 1, live_ = 0;
};

// The model's value ranges for rendering: the bricks' online macro-cells merged into one grid over the
// whole volume (a brick's cells mapped conservatively into the global cells they overlap), or none.
std::optional<ValueRangeGrid> merged_macrocells(const BrickedModel& m);

}  // namespace vnr
