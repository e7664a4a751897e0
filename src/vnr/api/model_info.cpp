// describe_model: what `vnr info` shows of a model (docs/CLI.md), for a single network and a multi-brick
// model alike.
#include "vnr/model.h"
#include "vnr/train/bricks.h"
#include "vnr/train/model_io.h"

namespace vnr {

namespace {

// The bricks' parameters and entries (what `vnr info` adds for a model directory).
void add_brick_info(const BrickedModel& bm, Json& j) {
  uint64_t params = 0, grid = 0, mlp = 0;
  Json bricks = Json::array();
  for (const BrickSpec& b : bm.plan.bricks) {
    const Network& n = *bm.bricks[size_t(b.index)]->net;
    params += n.n_params();
    grid += n.grid_params();
    mlp += n.mlp().n_params;
    Json e = brick_record(b);
    e["n_params"] = n.n_params();
    e["psnr"] = bm.bricks[size_t(b.index)]->training["brick"].value("psnr", 0.0);
    bricks.push_back(e);
  }
  j["format"] = "vnr-bricks";
  j["n_params"] = params;
  j["n_grid_params"] = grid;
  j["n_mlp_params"] = mlp;
  j["bricks"] = {{"grid", {bm.plan.grid.x, bm.plan.grid.y, bm.plan.grid.z}}, {"ghost", bm.plan.ghost},
                 {"seed", bm.plan.seed}, {"count", bm.plan.bricks.size()}, {"list", bricks}};
}

}  // namespace

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
  if (m.bricks) add_brick_info(*m.bricks, j);
  return j;
}

uint64_t hash_grid_entries(const Model& m) { return m.net && m.net->has_grid() ? m.net->grid().n_entries : 0; }

}  // namespace vnr
