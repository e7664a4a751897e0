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

// The keys read with json_get and written as they are: f(key, field) for each, the one list of them.
template <class Setup, class F>
void for_each_plain_key(Setup& s, F&& f) {
  f("volume", s.volume), f("target_ratio", s.target_ratio), f("target_psnr", s.target_psnr);
  f("residuals", s.residuals), f("bits_per_param", s.bits_per_param), f("qat_fraction", s.qat_fraction);
  f("rate_weight", s.rate_weight), f("learn_steps", s.learn_steps), f("batch", s.batch), f("seed", s.seed);
  f("device", s.device), f("mlp", s.mlp);
  f("precision", s.precision), f("macrocell_size", s.macrocell_size), f("sampler", s.data.sampler);
  f("blocks", s.data.blocks), f("refresh", s.data.refresh), f("output", s.session.output);
  f("checkpoint_every", s.session.checkpoint_every), f("cooldown", s.session.cooldown);
  f("max_error", s.session.error_bound.max_error), f("max_rel_error", s.session.error_bound.max_rel_error);
}

const std::set<std::string>& known_keys() {
  static const std::set<std::string> keys = [] {
    std::set<std::string> k = {"config", "steps",  "memory_budget", "block_dims", "grid_lr_scale", "nan",  // by hand
                               "dims",   "dtype",  "endian",        "offset",     "timestep",      "range"};
    TrainingSetup s;
    for_each_plain_key(s, [&k](const char* key, const auto&) { k.insert(key); });
    return k;
  }();
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
  for_each_plain_key(s, [&j](const char* key, auto& field) { field = json_get(j, key, field, kWhere); });
  if (auto it = j.find("config"); it != j.end()) {
    if (it->is_object()) s.config_json = *it;
    else if (it->is_string()) s.config = it->get<std::string>();
    else fail("{}: 'config' must be a preset name, a file or a tiny-cuda-nn config object, got {}", kWhere, it->dump());
  }
  s.steps = j.contains("steps") ? json_get<int64_t>(j, "steps", 0, kWhere) : s.steps;
  if (auto it = j.find("memory_budget"); it != j.end()) {
    s.data.memory_budget = it->is_string() ? parse_byte_size(it->get<std::string>()) : json_get<uint64_t>(j, "memory_budget", 0, kWhere);
    if (s.data.memory_budget == 0) fail("{}: 'memory_budget' must be positive", kWhere);
  }
  if (auto it = j.find("block_dims"); it != j.end()) s.data.block_dims = int3_of(*it, "block_dims");
  if (auto it = j.find("grid_lr_scale"); it != j.end())
    s.data.grid_lr_scale = it->is_number() ? fmt::format("{}", it->get<double>()) : json_get<std::string>(j, "grid_lr_scale", "", kWhere);
  read_raw_keys(j, s.raw);
  if (j.contains("nan")) s.load.non_finite = parse_non_finite_policy(json_get<std::string>(j, "nan", "", kWhere));
  check_values(s, nullptr);
  return s;
}

Json TrainingSetup::to_json() const {
  Json j = {{"config", config_json ? *config_json : Json(config)},
            {"grid_lr_scale", data.grid_lr_scale},
            {"nan", non_finite_policy_name(load.non_finite)}};
  for_each_plain_key(*this, [&j](const char* key, const auto& field) { j[key] = field; });
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
