#pragma once
// The field a renderer draws for a Model: its network, or a multi-brick model's blended bricks.
#include <memory>
#include "vnr/fields/bricked_field.h"
#include "vnr/fields/fields.h"
#include "vnr/train/bricks.h"

namespace vnr {

inline std::unique_ptr<RenderableField> make_model_field(const Model& model) {
  if (!model.bricks) return std::make_unique<NetworkField>(*model.net, model.dims);
  std::vector<const Network*> nets;
  for (auto& b : model.bricks->bricks) {
    if (b) b->net->set_inference_precision(model.net->inference_precision());  // Model::net carries it
    nets.push_back(b ? b->net.get() : nullptr);
  }
  return std::make_unique<BrickedField>(std::move(nets), model.bricks->layout);
}

}  // namespace vnr
