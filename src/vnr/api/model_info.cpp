// describe_model: what `vnr info` shows of a model (docs/CLI.md), for a single network and a multi-brick
// model alike.
#include "vnr/model.h"
#include "vnr/bricks.h"
#include "vnr/train/model_form.h"
#include "vnr/train/model_io.h"

namespace vnr {

Json describe_model(const Model& m, const std::string& path) {
  const Network& n = *m.net;
  const uint64_t bytes = model_file_bytes(path);
  Json j = {{"file", path},
            {"format", is_instantvnr_path(path) ? "instantvnr-bson" : "vnr"},
            {"dims", {m.dims.x, m.dims.y, m.dims.z}},
            {"dtype", dtype_name(m.source_dtype)},
            {"value_range", {m.lo, m.hi}},
            {"n_params", n.n_params()},
            {"n_mlp_params", n.mlp().n_params},
            {"n_grid_params", n.grid_params()},
            {"model_bytes", bytes},
            {"volume_bytes", source_bytes(m)},
            {"compression_ratio", compression_ratio(m, bytes)},
            {"config", n.config_json()},
            {"training", m.training}};
  if (m.macrocells) {
    int64_t occupied = 0;
    for (int64_t i = 0; i < m.macrocells->count(); ++i) occupied += !m.macrocells->empty(i);
    const Int3 cells = m.macrocells->cells;
    j["macrocells"] = {{"cell_size", m.macrocells->cell_size}, {"cells", {cells.x, cells.y, cells.z}},
                       {"occupied", occupied}};
  } else {
    j["macrocells"] = nullptr;
  }
  if (m.residuals) {  // only then: the keys of other models stay as they were
    const Residuals& r = *m.residuals;
    j["error_bound"] = {{"max_error", r.bound * (m.hi - m.lo)},
                        {"residual_nonzero", r.nonzero()},
                        {"residual_bytes", r.encoded ? r.encoded->bytes.size() : 0},
                        {"codec", r.encoded ? r.encoded->meta.value("codec", "") : ""}};
  }
  form_of(m).describe(m, j);  // a multi-brick model: its bricks
  return j;
}

uint64_t hash_grid_entries(const Model& m) { return m.net && m.net->has_grid() ? m.net->grid().n_entries : 0; }

}  // namespace vnr
