// Opening a multi-brick model, its blended point queries and region decodes, and its merged
// macro-cells (train/bricks.h).
#include <algorithm>
#include <cmath>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/train/bricks.h"
#include "vnr/train/model_form.h"

namespace vnr {

// Out of line, where BrickLayout is complete (vnr/bricks.h only names it).
BrickedModel::BrickedModel() = default;
BrickedModel::~BrickedModel() = default;

uint64_t BrickedModel::param_bytes() const {
  uint64_t n = 0;
  for (const auto& b : bricks)
    if (b) n += b->param_bytes();
  return n;
}

uint64_t BrickedModel::file_bytes() const { return model_file_bytes(dir); }

std::shared_ptr<BrickedModel> load_bricked_model(const std::string& dir, const std::vector<int>* only) {
  const std::string where = join_path(dir, "manifest.json");
  auto m = std::make_shared<BrickedModel>();
  m->dir = dir;
  m->manifest = parse_json_file(where);
  m->plan = read_manifest_plan(m->manifest, where);
  m->layout = layout_of(m->plan);
  try {
    m->source_dtype = parse_dtype(m->manifest.at("dtype").get<std::string>());
    m->lo = m->manifest.at("value_range").at(0).get<double>();
    m->hi = m->manifest.at("value_range").at(1).get<double>();
  } catch (const Error&) {
    throw;
  } catch (const std::exception&) {
    fail("{}: the manifest needs dtype and value_range [lo, hi]", where);
  }
  m->bricks.resize(m->plan.bricks.size());
  for (const BrickSpec& b : m->plan.bricks) {
    if (only && std::find(only->begin(), only->end(), b.index) == only->end()) continue;
    const std::string path = join_path(dir, b.file);
    if (!file_exists(path))
      fail("'{}': brick {} ({}) is missing; `vnr train ... --bricks ... --resume -o {}` trains the missing bricks", dir,
           b.index, b.file, dir);
    Model bm;
    try {
      bm = load_model(path);
    } catch (const Error& e) {
      fail("'{}': brick {} cannot be read ({}); `vnr train --resume` trains it again", dir, b.index, e.what());
    }
    if (!(bm.dims == b.trained.size()))
      fail("'{}': brick {} ({}) represents {}x{}x{} voxels, its trained box is {}x{}x{}", dir, b.index, b.file,
           bm.dims.x, bm.dims.y, bm.dims.z, b.trained.size().x, b.trained.size().y, b.trained.size().z);
    if (bm.lo != m->lo || bm.hi != m->hi)
      fail("'{}': brick {} was normalised with [{}, {}], the model with [{}, {}]", dir, b.index, bm.lo, bm.hi, m->lo, m->hi);
    m->bricks[size_t(b.index)] = std::move(bm);
  }
  return m;
}

void set_inference_precision(BrickedModel& m, Precision precision) {
  for (std::optional<Model>& b : m.bricks)
    if (b && b->net) b->net->set_inference_precision(precision);
}

Model model_of_bricks(std::shared_ptr<BrickedModel> bm) {
  Model m;
  for (const auto& b : bm->bricks)
    if (b) {
      m.net = std::make_unique<Network>(b->net->config_json());
      m.net->set_params_half(b->net->params_half());
      break;
    }
  if (!m.net) fail("'{}': no brick is loaded", bm->dir);
  m.dims = bm->plan.dims;
  m.source_dtype = bm->source_dtype;
  m.lo = bm->lo;
  m.hi = bm->hi;
  m.training = bm->manifest.value("training", Json());
  m.macrocells = merged_macrocells(*bm);
  m.bricks = std::move(bm);
  return m;
}

BrickLayout layout_of(const BrickPlan& plan) {
  BrickLayout l;
  l.dims = plan.dims;
  l.grid = plan.grid;
  for (const BrickSpec& b : plan.bricks) {
    l.owned.push_back(b.owned);
    l.trained.push_back(b.trained);
  }
  return l;
}

void bricked_points(const BrickedModel& m, const float* xyz, int64_t n, float* out, const BrickInfer& infer) {
  m.layout->blend_batch(
      n,
      [&](int64_t i, float* x, float* y, float* z) {
        *x = xyz[3 * i];
        *y = xyz[3 * i + 1];
        *z = xyz[3 * i + 2];
      },
      out,
      [&](int b, const float* local, int64_t count, float* vals) {
        if (!m.bricks[size_t(b)]) fail("brick {} of '{}' is needed here but not loaded", b, m.dir);
        if (infer) infer(b, local, count, vals);
        else m.bricks[size_t(b)]->net->infer(local, count, vals);
      });
}

void decode_bricked_region(const BrickedModel& m, Int3 out_dims, const Box3& region, float* out,
                           const BrickInfer& infer) {
  for (int a = 0; a < 3; ++a)
    if (out_dims[a] < 1 || region.lo[a] < 0 || region.hi[a] > out_dims[a] || region.lo[a] > region.hi[a])
      fail("decode region [{}, {}) x [{}, {}) x [{}, {}) is outside the {}x{}x{} grid", region.lo.x, region.hi.x,
           region.lo.y, region.hi.y, region.lo.z, region.hi.z, out_dims.x, out_dims.y, out_dims.z);
  const Int3 rs = region.size();
  const int64_t total = int64_t(rs.count());
  const int64_t chunk = int64_t(1) << 20;  // bounded memory whatever the region
  std::vector<float> xyz;
  for (int64_t first = 0; first < total; first += chunk) {
    const int64_t count = std::min(chunk, total - first);
    xyz.resize(size_t(count) * 3);
    for (int64_t k = 0; k < count; ++k) {
      const int64_t v = first + k;
      const int64_t ix = region.lo.x + v % rs.x, iy = region.lo.y + (v / rs.x) % rs.y, iz = region.lo.z + v / (rs.x * rs.y);
      xyz[size_t(3 * k)] = (float(ix) + 0.5f) / float(out_dims.x);  // voxel_centre's expression
      xyz[size_t(3 * k + 1)] = (float(iy) + 0.5f) / float(out_dims.y);
      xyz[size_t(3 * k + 2)] = (float(iz) + 0.5f) / float(out_dims.z);
    }
    bricked_points(m, xyz.data(), count, out + first, infer);
  }
}

namespace {
// Device bytes of one brick's GpuNetwork: half parameters and the buffers of the largest call of the
// blends (a decode's chunk of 2^20 points): coordinates, the padded encoding (half) and the outputs.
uint64_t brick_gpu_bytes(const Network& net) {
  const uint64_t points = uint64_t(1) << 20;
  return uint64_t(net.n_params()) * 2 + points * (3 * 4 + uint64_t(net.mlp().in_pad) * 2 + 4 * net.mlp().n_out);
}
}  // namespace

BrickGpuNetworks::BrickGpuNetworks(const BrickedModel& m, cuda::MlpPath mlp) : m_(m), mlp_(mlp) {
  nets_.resize(m.bricks.size());
  last_use_.assign(m.bricks.size(), 0);
  uint64_t each = 1;
  for (const auto& b : m.bricks)
    if (b) {
      cuda::check_supported(*b->net);
      each = std::max(each, brick_gpu_bytes(*b->net));
    }
  capacity_ = size_t(std::clamp<uint64_t>(cuda::free_memory_bytes() / 4 / each, 1, std::max<size_t>(m.bricks.size(), 1)));
}
BrickGpuNetworks::~BrickGpuNetworks() = default;

void BrickGpuNetworks::infer(int b, const float* xyz, int64_t n, float* out) {
  const size_t i = size_t(b);
  if (!nets_[i]) {
    if (live_ >= capacity_) {  // release the least recently used
      size_t lru = nets_.size();
      for (size_t j = 0; j < nets_.size(); ++j)
        if (nets_[j] && (lru == nets_.size() || last_use_[j] < last_use_[lru])) lru = j;
      nets_[lru].reset();
      --live_;
    }
    nets_[i] = std::make_unique<cuda::GpuNetwork>(*m_.bricks[i]->net, mlp_);
    ++live_;
  }
  last_use_[i] = ++clock_;
  nets_[i]->infer(xyz, n, out);
}

std::optional<ValueRangeGrid> merged_macrocells(const BrickedModel& m) {
  int cell_size = 0;
  for (const auto& b : m.bricks)
    if (b && b->macrocells) cell_size = b->macrocells->cell_size;
  if (cell_size == 0) return std::nullopt;
  ValueRangeGrid g(m.plan.dims, cell_size);
  g.clear();
  for (const BrickSpec& spec : m.plan.bricks) {
    const auto& bm = m.bricks[size_t(spec.index)];
    if (!bm || !bm->macrocells) return std::nullopt;  // a brick without ranges: no safe skipping anywhere
    const ValueRangeGrid& src = *bm->macrocells;
    for (int64_t cz = 0; cz < src.cells.z; ++cz)
      for (int64_t cy = 0; cy < src.cells.y; ++cy)
        for (int64_t cx = 0; cx < src.cells.x; ++cx) {
          const int64_t c = cx + src.cells.x * (cy + src.cells.y * cz);
          if (src.empty(c)) continue;
          // The brick cell's voxels [c*cs, (c+1)*cs] in global voxels, and the global cells they meet.
          const int64_t cc[3] = {cx, cy, cz};
          int64_t g0[3], g1[3];
          for (int a = 0; a < 3; ++a) {
            const int64_t v0 = spec.trained.lo[a] + cc[a] * src.cell_size - 1;
            const int64_t v1 = spec.trained.lo[a] + (cc[a] + 1) * src.cell_size + 1;
            g0[a] = std::clamp<int64_t>(v0 / cell_size, 0, g.cells[a] - 1);
            g1[a] = std::clamp<int64_t>(v1 / cell_size, 0, g.cells[a] - 1);
          }
          for (int64_t z = g0[2]; z <= g1[2]; ++z)
            for (int64_t y = g0[1]; y <= g1[1]; ++y)
              for (int64_t x = g0[0]; x <= g1[0]; ++x) {
                const int64_t d = x + g.cells.x * (y + g.cells.y * z);
                g.lo[size_t(d)] = std::min(g.lo[size_t(d)], src.lo[size_t(c)]);
                g.hi[size_t(d)] = std::max(g.hi[size_t(d)], src.hi[size_t(c)]);
              }
        }
  }
  return g;
}

namespace {

// A multi-brick model's bricks, set to the model's inference precision (Model::net carries it).
BrickedModel& bricks_at_model_precision(const Model& m) {
  set_inference_precision(*m.bricks, m.net->inference_precision());
  return *m.bricks;
}

// A multi-brick model's evaluation: its bricks blended, each brick's network on the device.
class BricksEvaluator final : public ModelEvaluator {
public:
  BricksEvaluator(const Model& model, Device device, cuda::MlpPath mlp) : m_(bricks_at_model_precision(model)) {
    if (device == Device::Cuda) gpus_ = std::make_unique<BrickGpuNetworks>(m_, mlp);
  }
  void points(const float* xyz, int64_t n, float* out) override { bricked_points(m_, xyz, n, out, infer()); }
  void slices(Int3 dims, int64_t z0, int64_t z1, float* out) override {
    decode_bricked_region(m_, dims, Box3{{0, 0, z0}, {dims.x, dims.y, z1}}, out, infer());
  }

private:
  BrickInfer infer() { return gpus_ ? gpus_->fn() : BrickInfer{}; }
  const BrickedModel& m_;
  std::unique_ptr<BrickGpuNetworks> gpus_;
};

// The bricks' parameters and entries (what `vnr info` adds for a model directory).
void describe_bricks(const BrickedModel& bm, Json& j) {
  uint64_t params = 0, grid = 0, mlp = 0;
  Json list = Json::array();
  for (const BrickSpec& b : bm.plan.bricks) {
    const Network& n = *bm.bricks[size_t(b.index)]->net;
    params += n.n_params();
    grid += n.grid_params();
    mlp += n.mlp().n_params;
    Json e = brick_record(b);
    e["n_params"] = n.n_params();
    e["psnr"] = bm.bricks[size_t(b.index)]->training["brick"].value("psnr", 0.0);
    list.push_back(e);
  }
  j["format"] = "vnr-bricks";
  j["n_params"] = params;
  j["n_grid_params"] = grid;
  j["n_mlp_params"] = mlp;
  j["bricks"] = {{"grid", {bm.plan.grid.x, bm.plan.grid.y, bm.plan.grid.z}}, {"ghost", bm.plan.ghost},
                 {"seed", bm.plan.seed}, {"count", bm.plan.bricks.size()}, {"list", list}};
}

class BricksForm final : public ModelForm {
public:
  uint64_t n_params(const Model& m) const override { return m.bricks->param_bytes() / 2; }
  bool trainable() const override { return false; }  // trained brick by brick (train_bricks)
  Device evaluation_device(const Model&, Device) const override { return Device::Cpu; }
  std::unique_ptr<ModelEvaluator> evaluator(const Model& m, Device device, cuda::MlpPath mlp) const override {
    return std::make_unique<BricksEvaluator>(m, device, mlp);
  }
  std::string gpu_render_reason(const Model& m) const override {
    return gpu_decode_reason("a multi-brick model", m.dims);
  }
  void describe(const Model& m, Json& j) const override { describe_bricks(*m.bricks, j); }
  void check_savable(const Model&, const std::string& path) const override {
    fail("'{}': a multi-brick model is a directory of brick files written by `vnr train --bricks`; it cannot be "
         "saved as one model file", path);
  }
  void make_field(const Model& m, ModelFieldMaker& maker) const override {
    maker.bricks(m, bricks_at_model_precision(m));
  }
};

}  // namespace

const ModelForm& bricks_form() {
  static const BricksForm form;
  return form;
}

}  // namespace vnr
