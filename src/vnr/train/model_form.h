#pragma once
// What a single network and a multi-brick model do differently, behind one interface, so that the code
// that queries, decodes, describes, saves or renders a Model does not ask which it is. form_of() is the
// one place that asks; the multi-brick form is part of the bricks' implementation (train/bricks_model.cpp),
// the single network's is train/model_form.cpp. A third kind of model is a third ModelForm.
#include <cstdint>
#include <memory>
#include <string>
#include "vnr/cuda/cuda.h"
#include "vnr/device.h"
#include "vnr/json.h"
#include "vnr/math.h"
#include "vnr/model.h"

namespace vnr {

// A model's network part on one device, without residuals (the Decoder adds those): points, and voxel
// centres ((i + 0.5) / n per axis) given by z-slab or by index.
class ModelEvaluator {
public:
  virtual ~ModelEvaluator() = default;
  virtual void points(const float* xyz, int64_t n, float* out) = 0;
  virtual void slices(Int3 dims, int64_t z0, int64_t z1, float* out) = 0;
  // By default the centres are gathered and go through points().
  virtual void voxels(Int3 dims, const int64_t* voxel_index, int64_t n, float* out);
  virtual cuda::GpuNetwork* gpu() { return nullptr; }  // a single network's GPU copy (benchmarks time it)
};

// The evaluator of one network: its CPU inference, or its GPU copy (made here).
std::unique_ptr<ModelEvaluator> network_evaluator(const Network& net, Device device,
                                                  cuda::MlpPath mlp = cuda::MlpPath::Auto);

// What a renderer's field factory (api, a layer above this one) is handed of a model: one call, for the
// model's kind. The field types cannot be named here.
class ModelFieldMaker {
public:
  virtual ~ModelFieldMaker() = default;
  virtual void network(const Model& model) = 0;
  virtual void bricks(const Model& model, BrickedModel& bricks) = 0;
};

class ModelForm {
public:
  virtual ~ModelForm() = default;
  virtual uint64_t n_params(const Model& m) const = 0;  // every brick's
  virtual bool trainable() const = 0;                   // by a session (bricks train brick by brick)
  // The device a file evaluation decodes on when `asked` was asked for; fails before anything is read when
  // the model cannot run there.
  virtual Device evaluation_device(const Model& m, Device asked) const = 0;
  // The evaluator on `device`, at the model's inference precision.
  virtual std::unique_ptr<ModelEvaluator> evaluator(const Model& m, Device device, cuda::MlpPath mlp) const = 0;
  // Why the model cannot render on the GPU ("" when it can).
  virtual std::string gpu_render_reason(const Model& m) const = 0;
  // describe_model's keys that differ by kind (vnr/model.h), over the ones of the single network.
  virtual void describe(const Model& m, Json& j) const = 0;
  // Fails naming `path` when the model cannot be saved as one model file.
  virtual void check_savable(const Model& m, const std::string& path) const = 0;
  virtual void make_field(const Model& m, ModelFieldMaker& maker) const = 0;
};

const ModelForm& form_of(const Model& m);
const ModelForm& network_form();  // train/model_form.cpp
const ModelForm& bricks_form();   // train/bricks_model.cpp

// Why a decode of dims voxels (float32) cannot be held for rendering on the GPU ("" when it can): it must fit
// a quarter of the GPU's free memory and the host's memory. `what` names the decoded thing.
std::string gpu_decode_reason(const std::string& what, Int3 dims);

}  // namespace vnr
