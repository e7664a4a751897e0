#include "vnr/train/model.h"
#include "vnr/nn/mlp_layout.h"
#include <cstdio>
#include <cstring>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/train/bricks.h"
#include "vnr/train/model_form.h"

namespace vnr {

// Out of line, where the members' types are complete (vnr/model.h only names them).
Model::Model() = default;
Model::~Model() = default;
Model::Model(Model&&) noexcept = default;
Model& Model::operator=(Model&&) noexcept = default;

bool is_instantvnr_path(const std::string& path) {
  const std::string e = extension_of(path);
  return e == ".bson" || e == ".json";
}

Model create_model(const ModelConfig& config, Int3 dims, DType source_dtype, double lo, double hi, uint32_t seed) {
  Model model;
  model.net = std::make_unique<Network>(config);
  model.dims = dims;
  model.source_dtype = source_dtype;
  model.lo = lo;
  model.hi = hi;
  model.net->init_params(seed);
  return model;
}

void round_params_to_stored(Model& m) {
  if (m.net) m.net->set_params_half(m.net->params_half());
}

ModelFile model_file_without_params(const Model& m) {
  ModelFile f;
  f.config = m.net->config_json();
  f.dims = m.dims;
  f.source_dtype = m.source_dtype;
  f.lo = m.lo;
  f.hi = m.hi;
  f.training = m.training;
  if (m.macrocells) {
    f.macrocell_dims = m.macrocells->cells;
    f.macrocell_ranges = m.macrocells->to_pairs();
  }
  return f;
}

ModelFile model_file(const Model& m) {
  ModelFile f = model_file_without_params(m);
  f.params = m.net->params_half();
  f.param_segments = m.param_segments;  // compressed storage (format 3) when set
  f.compact_macrocells = !m.param_segments.empty();
  if (m.residuals) {
    const EncodedResiduals e = m.residuals->encoded ? *m.residuals->encoded : encode_residuals(*m.residuals);
    f.residuals_meta = e.meta;
    f.residuals_bytes = e.bytes;
  }
  return f;
}

uint64_t model_file_bytes(const Model& m) { return vnr_file_bytes(model_file(m)); }

void save_model(const std::string& path, const Model& m) {
  form_of(m).check_savable(m, path);
  if (m.residuals && is_instantvnr_path(path))
    fail("'{}': instantvnr's format cannot hold error-bound residuals; save the model as .vnr", path);
  const ModelFile f = model_file(m);
  if (is_instantvnr_path(path)) write_instantvnr(path, f);
  else write_vnr(path, f);
}

Model load_model(const std::string& path) {
  if (is_bricked_model_dir(path)) return model_of_bricks(load_bricked_model(path));  // docs/MODEL_FORMAT.md
  ModelFile f = read_model(path);
  // Counted before the network exists: a damaged config must not allocate and initialise a large
  // network only to be refused (a 300-byte file took 0.9 s under the fuzzer).
  const ModelConfig config = ModelConfig::from_json(f.config);
  const uint64_t needed = count_params(config);
  if (f.params.size() != needed)
    fail("'{}': the file holds {} parameters but its configuration needs {}", path, f.params.size(), needed);
  Model m;
  m.net = std::make_unique<Network>(config);
  m.net->set_params_half(f.params);
  m.dims = f.dims;
  m.source_dtype = f.source_dtype;
  m.lo = f.lo;
  m.hi = f.hi;
  m.training = f.training;
  if (!f.residuals_bytes.empty() || !f.residuals_meta.is_null()) {
    m.residuals = decode_residuals(f.residuals_meta, f.residuals_bytes, f.dims, "'" + path + "'");
    m.residuals->encoded = std::make_shared<const EncodedResiduals>(EncodedResiduals{f.residuals_meta, f.residuals_bytes});
  }
  m.param_segments = f.param_segments;
  if (!(f.macrocell_dims == Int3{}) && f.dims.count() > 0) {
    try {
      m.macrocells = ValueRangeGrid::from_pairs(f.dims, f.macrocell_dims, f.macrocell_ranges);
    } catch (const Error& e) {
      fail("'{}': {}", path, e.what());
    }
  }
  return m;
}

bool model_file_has_value_range(const std::string& path) {
  // The .vnr magic (docs/MODEL_FORMAT.md); vnr always writes value_range into that header.
  if (is_bricked_model_dir(path)) return true;  // the manifest's value_range
  char magic[8] = {};
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return false;
  size_t got = std::fread(magic, 1, sizeof magic, f);
  std::fclose(f);
  return got == sizeof magic && std::memcmp(magic, "VNRMODEL", sizeof magic) == 0;
}

}  // namespace vnr
