// vnr::Model's constructors, queries and decodes (the train layer's Model, Network and GpuNetwork).
#include "vnr/model.h"
#include <atomic>
#include "vnr/error.h"
#include "vnr/core/parallel.h"
#include "vnr/train/decoder.h"
#include "vnr/train/evaluate.h"
#include "vnr/train/model.h"
#include "vnr/units.h"
#include "vnr/volume_writer.h"

namespace vnr {

const ModelConfig& model_config(const Model& m) {
  if (!m.net) fail("the model has no network");
  return m.net->config();
}
void set_inference_precision(Model& m, Precision precision) {
  if (!m.net) fail("the model has no network");
  m.net->set_inference_precision(precision);
}
Precision inference_precision(const Model& m) {
  if (!m.net) fail("the model has no network");
  return m.net->inference_precision();
}

Model create_model(const ModelConfig& config, const Volume& volume, uint32_t seed) {
  return create_model(config, volume.dims, volume.source_dtype, volume.lo, volume.hi, seed);
}

uint64_t source_bytes(const Model& m) { return m.dims.count() * dtype_size(m.source_dtype); }

double compression_ratio(const Model& m, uint64_t model_bytes) {
  return double(source_bytes(m)) / double(model_bytes ? model_bytes : m.param_bytes());
}

ModelQuery::ModelQuery(const Model& model, Device device, cuda::MlpPath mlp) : model_(model), device_(device) {
  if (!model.net) fail("the model has no network");
  decoder_ = std::make_unique<Decoder>(model, device, mlp);
}
ModelQuery::~ModelQuery() = default;

cuda::GpuNetwork* ModelQuery::gpu() { return decoder_->gpu(); }

namespace {
void convert_units(const Model& m, ValueUnits units, float* v, int64_t n) {
  if (units != ValueUnits::Original) return;
  for (int64_t i = 0; i < n; ++i) v[i] = to_original_units(m, v[i]);  // `vnr decode`'s expression
}
void check_grid(Int3 dims, int64_t z0, int64_t z1) {
  if (dims.x < 1 || dims.y < 1 || dims.z < 1) fail("decode dims must be positive, got {}x{}x{}", dims.x, dims.y, dims.z);
  if (z0 < 0 || z1 > dims.z || z0 > z1) fail("slab [{}, {}) is outside 0..{}", z0, z1, dims.z);
}
}  // namespace

void ModelQuery::points(const float* xyz, int64_t n, float* out, ValueUnits units) {
  if (n <= 0) return;
  decoder_->points(xyz, n, out);
  convert_units(model_, units, out, n);
}

void ModelQuery::slab(Int3 dims, int64_t z0, int64_t z1, float* out, ValueUnits units) {
  check_grid(dims, z0, z1);
  if (z1 == z0) return;
  decoder_->slices(dims, z0, z1, out);  // residuals at their dims on the CPU reference, whatever the device
  convert_units(model_, units, out, dims.x * dims.y * (z1 - z0));
}

void check_unit_points(const float* xyz, int64_t n, int64_t first) {
  std::atomic<int64_t> bad{INT64_MAX};
  parallel_for_range(3 * n, int64_t(1) << 18, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i)
      if (!(xyz[i] >= 0.f && xyz[i] <= 1.f)) {  // also catches NaN
        int64_t seen = bad.load();
        while (i < seen && !bad.compare_exchange_weak(seen, i)) {
        }
        return;
      }
  });
  const int64_t i = bad.load();
  if (i != INT64_MAX)
    fail("points must be finite and in [0, 1]^3; point {} has {} = {}", first + i / 3, "xyz"[i % 3], xyz[i]);
}

void check_decode_fits_memory(Int3 dims, int64_t slices) {
  if (dims.x < 1 || dims.y < 1 || dims.z < 1) fail("decode dims must be positive, got {}x{}x{}", dims.x, dims.y, dims.z);
  const double bytes = double(dims.x) * double(dims.y) * double(slices) * sizeof(float);
  const uint64_t available = available_memory_bytes();
  if (bytes <= double(available)) return;
  fail("decoding {}x{}x{} ({} z-slices at a time) needs {} of float32, exceeding the memory available ({})", dims.x,
       dims.y, dims.z, slices, human_bytes(bytes), human_bytes(double(available)));
}

Volume ModelQuery::decode(Int3 dims) {
  if (dims.x == 0 || dims.y == 0 || dims.z == 0) dims = model_.dims;
  check_decode_fits_memory(dims, dims.z);
  Volume v;
  v.dims = dims;
  v.source_dtype = model_.source_dtype;
  v.lo = model_.lo;
  v.hi = model_.hi;
  v.data.resize(dims.count());
  slab(dims, 0, dims.z, v.data.data());
  return v;
}

void ModelQuery::for_each_slab(Int3 dims, const std::function<void(int64_t, int64_t, const float*)>& sink) {
  // (in double: hostile dims must not overflow before check_decode_fits_memory refuses them)
  const int64_t slices = std::max<int64_t>(1, int64_t(double(int64_t(1) << 24) / (double(dims.x) * double(dims.y))));
  check_decode_fits_memory(dims, std::min<int64_t>(slices, dims.z));
  std::vector<float> buf(size_t(dims.x * dims.y * std::min<int64_t>(slices, dims.z)));
  for (int64_t z0 = 0; z0 < dims.z; z0 += slices) {
    const int64_t z1 = std::min(dims.z, z0 + slices);
    slab(dims, z0, z1, buf.data(), ValueUnits::Original);
    sink(z0, z1, buf.data());
  }
}

void ModelQuery::decode_to_file(const std::string& path, Int3 dims, DType dtype,
                                const std::function<void(int64_t, int64_t)>& progress) {
  if (dims.x == 0 || dims.y == 0 || dims.z == 0) dims = model_.dims;
  check_decode_fits_memory(dims, 1);  // before the writer creates anything
  // Voxel size relative to the model's grid (model files carry no physical spacing).
  const Vec3f spacing{float(double(model_.dims.x) / double(dims.x)), float(double(model_.dims.y) / double(dims.y)),
                      float(double(model_.dims.z) / double(dims.z))};
  VolumeWriter w(path, dims, dtype, spacing, std::make_pair(model_.lo, model_.hi));
  for_each_slab(dims, [&](int64_t z0, int64_t z1, const float* values) {
    w.write_slices(values, z1 - z0);
    if (progress) progress(z1, dims.z);
  });
  w.commit();
}

EvalResult evaluate_model(const Model& model, const Volume& volume, bool with_ssim, Device device) {
  return evaluate(model, volume, with_ssim, device);
}

}  // namespace vnr
