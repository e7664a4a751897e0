// TrainingSetup's checks and its JSON form (train/session.h): the settings of one training run as a
// user gives them, flat as the CLI's options.
#include <cmath>
#include <set>
#include "vnr/error.h"
#include "vnr/units.h"
#include "vnr/cuda/cuda.h"
#include "vnr/nn/json_get.h"
#include "vnr/nn/network.h"
#include "vnr/train/session.h"

namespace vnr {

namespace {

const char* const kWhere = "training settings";

const std::set<std::string>& known_keys() {
  static const std::set<std::string> keys = {
      "volume", "config", "target_ratio", "target_psnr", "residuals", "bits_per_param", "qat_fraction",
      "rate_weight", "batch", "seed", "device", "mlp", "precision", "macrocell_size", "steps", "sampler",
      "memory_budget", "blocks", "refresh", "block_dims", "grid_lr_scale", "output", "checkpoint_every",
      "cooldown", "max_error", "max_rel_error", "dims", "dtype", "endian", "offset", "timestep", "range", "nan"};
  return keys;
}

Int3 int3_of(const Json& j, const char* key) {
  if (!j.is_array() || j.size() != 3 || !j[0].is_number_integer() || !j[1].is_number_integer() ||
      !j[2].is_number_integer() || j[0].get<int64_t>() < 1 || j[1].get<int64_t>() < 1 || j[2].get<int64_t>() < 1)
    fail("{}: '{}' must be [x, y, z] (positive integers), got {}", kWhere, key, j.dump());
  return Int3{j[0].get<int64_t>(), j[1].get<int64_t>(), j[2].get<int64_t>()};
}

// The raw-volume keys (RawOptions; only what a key sets).
void read_raw_keys(const Json& j, RawOptions& raw) {
  if (auto it = j.find("dims"); it != j.end()) raw.dims = int3_of(*it, "dims");
  if (j.contains("dtype")) raw.dtype = json_get<std::string>(j, "dtype", "", kWhere);
  if (j.contains("endian")) raw.endian = json_get<std::string>(j, "endian", "", kWhere);
  if (j.contains("offset")) raw.offset = json_get<uint64_t>(j, "offset", 0, kWhere);
  if (j.contains("timestep")) raw.timestep = json_get<int>(j, "timestep", 0, kWhere);
  if (auto it = j.find("range"); it != j.end()) {
    if (!it->is_array() || it->size() != 2 || !(*it)[0].is_number() || !(*it)[1].is_number() ||
        !((*it)[0].get<double>() <= (*it)[1].get<double>()))
      fail("{}: 'range' must be [lo, hi] with lo <= hi, got {}", kWhere, it->dump());
    raw.range_lo = (*it)[0].get<double>();
    raw.range_hi = (*it)[1].get<double>();
  }
}

// The checks, naming each setting with name(key): the CLI's options, or the JSON and Python keys.
void check_values(const TrainingSetup& s, std::string (*name)(const std::string&)) {
  auto n = [name](const char* key) { return name ? name(key) : std::string(key); };
  if (s.batch <= 0 || s.batch % kChunk != 0) fail("{} must be a positive multiple of {}, got {}", n("batch"), kChunk, s.batch);
  if (s.steps < -1) fail("{} must be non-negative, got {}", n("steps"), s.steps);
  if (s.macrocell_size < 0) fail("{} must be 0 (none) or positive, got {}", n("macrocell_size"), s.macrocell_size);
  if (s.session.checkpoint_every < 0)
    fail("{} must be non-negative, got {}", n("checkpoint_every"), s.session.checkpoint_every);
  if (s.data.blocks < 0 || s.data.refresh < 0) fail("{} and {} must be positive", n("blocks"), n("refresh"));
  if (s.target_ratio < 0 || !std::isfinite(s.target_ratio))
    fail("{} must be positive, got {}", n("target_ratio"), s.target_ratio);
  if (s.target_psnr < 0 || !std::isfinite(s.target_psnr)) fail("{} must be positive, got {}", n("target_psnr"), s.target_psnr);
  if (!(s.qat_fraction >= 0 && s.qat_fraction <= 1))
    fail("{} must be in [0, 1], got {}", n("qat_fraction"), s.qat_fraction);
  if (!(s.rate_weight >= 0 && s.rate_weight <= 100))
    fail("{} must be in [0, 100], got {}", n("rate_weight"), s.rate_weight);
  if (s.residuals != "auto" && s.residuals != "off") fail("{} must be auto or off, got '{}'", n("residuals"), s.residuals);
  if (!(s.bits_per_param > 0 && s.bits_per_param <= 16))
    fail("{} (bits per parameter) must be in (0, 16], got {}", n("bits_per_param"), s.bits_per_param);
  if (!(s.session.cooldown >= 0 && s.session.cooldown <= 1))
    fail("{} must be in [0, 1], got {}", n("cooldown"), s.session.cooldown);
  if (!(s.session.error_bound.max_error >= 0 && s.session.error_bound.max_rel_error >= 0))
    fail("{} and {} must be positive", n("max_error"), n("max_rel_error"));
}

}  // namespace

void check_training_setup(const TrainingSetup& s) {
  check_values(s, option_name_of);
  if (s.device == "cuda") cuda::require_device();
}

TrainingSetup TrainingSetup::from_json(const Json& j) {
  json_check_keys(j, known_keys(), kWhere);
  TrainingSetup s;
  s.volume = json_get(j, "volume", s.volume, kWhere);
  if (auto it = j.find("config"); it != j.end()) {
    if (it->is_object()) s.config_json = *it;
    else if (it->is_string()) s.config = it->get<std::string>();
    else fail("{}: 'config' must be a preset name, a file or a tiny-cuda-nn config object, got {}", kWhere, it->dump());
  }
  s.target_ratio = json_get(j, "target_ratio", s.target_ratio, kWhere);
  s.target_psnr = json_get(j, "target_psnr", s.target_psnr, kWhere);
  s.residuals = json_get(j, "residuals", s.residuals, kWhere);
  s.bits_per_param = json_get(j, "bits_per_param", s.bits_per_param, kWhere);
  s.qat_fraction = json_get(j, "qat_fraction", s.qat_fraction, kWhere);
  s.rate_weight = json_get(j, "rate_weight", s.rate_weight, kWhere);
  s.batch = json_get<int64_t>(j, "batch", s.batch, kWhere);
  s.seed = json_get(j, "seed", s.seed, kWhere);
  s.device = json_get(j, "device", s.device, kWhere);
  s.mlp = json_get(j, "mlp", s.mlp, kWhere);
  s.precision = json_get(j, "precision", s.precision, kWhere);
  s.macrocell_size = json_get(j, "macrocell_size", s.macrocell_size, kWhere);
  s.steps = j.contains("steps") ? json_get<int64_t>(j, "steps", 0, kWhere) : s.steps;
  s.data.sampler = json_get(j, "sampler", s.data.sampler, kWhere);
  if (auto it = j.find("memory_budget"); it != j.end()) {
    s.data.memory_budget = it->is_string() ? parse_byte_size(it->get<std::string>()) : json_get<uint64_t>(j, "memory_budget", 0, kWhere);
    if (s.data.memory_budget == 0) fail("{}: 'memory_budget' must be positive", kWhere);
  }
  s.data.blocks = json_get<int64_t>(j, "blocks", s.data.blocks, kWhere);
  s.data.refresh = json_get<int64_t>(j, "refresh", s.data.refresh, kWhere);
  if (auto it = j.find("block_dims"); it != j.end()) s.data.block_dims = int3_of(*it, "block_dims");
  if (auto it = j.find("grid_lr_scale"); it != j.end())
    s.data.grid_lr_scale = it->is_number() ? fmt::format("{}", it->get<double>()) : json_get<std::string>(j, "grid_lr_scale", "", kWhere);
  s.session.output = json_get(j, "output", s.session.output, kWhere);
  s.session.checkpoint_every = json_get<int64_t>(j, "checkpoint_every", s.session.checkpoint_every, kWhere);
  s.session.cooldown = json_get(j, "cooldown", s.session.cooldown, kWhere);
  s.session.error_bound.max_error = json_get(j, "max_error", s.session.error_bound.max_error, kWhere);
  s.session.error_bound.max_rel_error = json_get(j, "max_rel_error", s.session.error_bound.max_rel_error, kWhere);
  read_raw_keys(j, s.raw);
  if (j.contains("nan")) s.load.non_finite = parse_non_finite_policy(json_get<std::string>(j, "nan", "", kWhere));
  check_values(s, nullptr);
  return s;
}

Json TrainingSetup::to_json() const {
  Json j = {{"volume", volume},
            {"config", config_json ? *config_json : Json(config)},
            {"target_ratio", target_ratio},
            {"target_psnr", target_psnr},
            {"residuals", residuals},
            {"bits_per_param", bits_per_param},
            {"qat_fraction", qat_fraction},
            {"rate_weight", rate_weight},
            {"batch", batch},
            {"seed", seed},
            {"device", device},
            {"mlp", mlp},
            {"precision", precision},
            {"macrocell_size", macrocell_size},
            {"sampler", data.sampler},
            {"blocks", data.blocks},
            {"refresh", data.refresh},
            {"grid_lr_scale", data.grid_lr_scale},
            {"output", session.output},
            {"checkpoint_every", session.checkpoint_every},
            {"cooldown", session.cooldown},
            {"max_error", session.error_bound.max_error},
            {"max_rel_error", session.error_bound.max_rel_error},
            {"nan", non_finite_policy_name(load.non_finite)}};
  if (steps >= 0) j["steps"] = steps;
  if (data.memory_budget > 0) j["memory_budget"] = data.memory_budget;
  if (data.block_dims) j["block_dims"] = {data.block_dims->x, data.block_dims->y, data.block_dims->z};
  if (raw.dims) j["dims"] = {raw.dims->x, raw.dims->y, raw.dims->z};
  if (raw.dtype) j["dtype"] = *raw.dtype;
  if (raw.endian) j["endian"] = *raw.endian;
  if (raw.offset) j["offset"] = *raw.offset;
  if (raw.timestep) j["timestep"] = *raw.timestep;
  if (raw.range_lo && raw.range_hi) j["range"] = {*raw.range_lo, *raw.range_hi};
  return j;
}

}  // namespace vnr
