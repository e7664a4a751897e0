#pragma once
// What a training run learns from and starts with: the training data (a volume in memory, an
// out-of-core block buffer or a memory map, chosen by the memory budget), the out-of-core grid
// learning-rate scaling, and a fresh model. Messages for people are handed to a callback, not printed.
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include "vnr/model_config.h"
#include "vnr/training_options.h"
#include "vnr/train/model_io.h"
#include "vnr/train/sampler.h"
#include "vnr/train/streaming_samplers.h"
#include "vnr/volume/raw_access.h"
#include "vnr/volume/stream.h"
#include "vnr/volume/volume.h"

namespace vnr {

// Where the training samples come from, and the volume when it is in memory.
struct TrainingData {
  std::string kind;  // incore | outofcore | mmap
  std::shared_ptr<Sampler> sampler;
  // incore only; shared, so that a caller holding the volume in memory (the Python module) trains on it
  // without a copy
  std::shared_ptr<const Volume> vol;
  std::shared_ptr<OutOfCoreSampler> out_of_core;   // outofcore only
  std::shared_ptr<const RawVolumeFile> raw_file;   // outofcore only
  VolumeDesc desc;
  LoadOptions load;
  uint64_t memory_budget = 0;
  Int3 dims;
  DType dtype = DType::Float32;
  double lo = 0, hi = 1;
  uint64_t source_bytes() const { return dims.count() * dtype_size(dtype); }
};

// Opens the volume `desc` (named `name` in messages) for training: loads it (incore), or prepares the
// random-access samplers (the value range from the descriptor or one streaming pass; the out-of-core
// buffer filled). Fails with one line for options that do not fit the data.
TrainingData open_training_data(const std::string& name, const VolumeDesc& desc, const LoadOptions& load,
                                const TrainingDataOptions& opts, const MessageFn& message = {});
// The same for a volume already in memory (named `name` in messages), sampled in core and shared, not
// copied.
TrainingData in_memory_training_data(const std::string& name, std::shared_ptr<const Volume> volume,
                                     uint64_t memory_budget, const MessageFn& message = {});

// The out-of-core grid learning rate: a buffer concentrates each step's samples on the resident
// fraction f of the volume, so every hash-grid entry it touches gets many consistent gradients and Adam
// moves it a full step each step, and the loss can spike. `scale` "auto" multiplies the grid's
// (non-matrix) learning rate by f, at least 0.1; a number multiplies it by that. The default "1" keeps
// the configured rate: an under-fitting run loses quality with a smaller one. `note` (may be null)
// describes a change, empty when there is none.
ModelConfig scale_grid_learning_rate(ModelConfig config, const std::string& scale, const OutOfCoreSampler& sampler,
                                     std::string* note);

}  // namespace vnr
