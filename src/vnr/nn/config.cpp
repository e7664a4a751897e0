#include "vnr/model_config.h"
#include "vnr/nn/mlp_bf16.h"
#include <cmath>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/nn/encoding.h"
#include "vnr/nn/json_get.h"

namespace vnr {
namespace {

Activation parse_activation(const std::string& s, const char* where) {
  static const std::pair<const char*, Activation> t[] = {
      {"None", Activation::None}, {"ReLU", Activation::ReLU}, {"Exponential", Activation::Exponential},
      {"Sine", Activation::Sine}, {"Sigmoid", Activation::Sigmoid}, {"Squareplus", Activation::Squareplus},
      {"Softplus", Activation::Softplus}};
  for (auto& [n, a] : t)
    if (iequals(s, n)) return a;
  fail("{}: unsupported activation '{}' (allowed: None, ReLU, Exponential, Sine, Sigmoid, Squareplus, Softplus)",
       where, s);
}

NetworkConfig parse_network(const Json& j) {
  const char* w = "network";
  if (!j.is_object()) fail("config: 'network' must be an object");
  NetworkConfig n;
  std::string otype = json_get<std::string>(j, "otype", "", w);
  if (iequals(otype, "FullyFusedMLP")) n.fully_fused = true;
  else if (iequals(otype, "CutlassMLP") || iequals(otype, "MLP")) n.fully_fused = false;
  else fail("network: unsupported otype '{}' (allowed: FullyFusedMLP, CutlassMLP, MLP)", otype);
  n.n_neurons = json_get<uint32_t>(j, "n_neurons", 128u, w);
  n.n_hidden_layers = json_get<uint32_t>(j, "n_hidden_layers", 5u, w);
  if (n.fully_fused && n.n_neurons != 16 && n.n_neurons != 32 && n.n_neurons != 64 && n.n_neurons != 128)
    fail("network: FullyFusedMLP supports n_neurons 16, 32, 64 or 128, got {} (use CutlassMLP for other widths)",
         n.n_neurons);
  if (n.n_neurons < 1 || n.n_neurons > 1024) fail("network: n_neurons must be in 1..1024, got {}", n.n_neurons);
  if (n.n_hidden_layers < 1 || n.n_hidden_layers > 32)
    fail("network: n_hidden_layers must be in 1..32, got {}", n.n_hidden_layers);
  n.activation = parse_activation(json_get<std::string>(j, "activation", "ReLU", w), "network.activation");
  if (n.activation != Activation::ReLU && n.activation != Activation::None)
    fail("network: unsupported hidden activation '{}' on the CPU backend (allowed: ReLU, None)",
         activation_name(n.activation));
  n.output_activation =
      parse_activation(json_get<std::string>(j, "output_activation", "None", w), "network.output_activation");
  return n;
}

LossType parse_loss(const Json& j) {
  std::string otype = j.is_object() ? json_get<std::string>(j, "otype", "RelativeL2", "loss") : "RelativeL2";
  if (iequals(otype, "L1")) return LossType::L1;
  if (iequals(otype, "L2")) return LossType::L2;
  if (iequals(otype, "RelativeL2")) return LossType::RelativeL2;
  if (iequals(otype, "RelativeL1")) return LossType::RelativeL1;
  fail("loss: unsupported otype '{}' (allowed: L1, L2, RelativeL2, RelativeL1)", otype);
}

AdamConfig parse_adam(const Json& j) {
  const char* w = "optimizer";
  std::string otype = json_get<std::string>(j, "otype", "Adam", w);
  if (!iequals(otype, "Adam")) fail("optimizer: unsupported otype '{}' (allowed: Adam, ExponentialDecay)", otype);
  AdamConfig a;
  a.learning_rate = json_get<float>(j, "learning_rate", a.learning_rate, w);
  a.beta1 = json_get<float>(j, "beta1", a.beta1, w);
  a.beta2 = json_get<float>(j, "beta2", a.beta2, w);
  a.epsilon = json_get<float>(j, "epsilon", a.epsilon, w);
  a.l2_reg = json_get<float>(j, "l2_reg", a.l2_reg, w);
  a.relative_decay = json_get<float>(j, "relative_decay", a.relative_decay, w);
  a.absolute_decay = json_get<float>(j, "absolute_decay", a.absolute_decay, w);
  a.adabound = json_get<bool>(j, "adabound", a.adabound, w);
  a.non_matrix_learning_rate_factor =
      json_get<float>(j, "non_matrix_learning_rate_factor", a.non_matrix_learning_rate_factor, w);
  a.optimize_matrix_params = json_get<bool>(j, "optimize_matrix_params", true, w);
  a.optimize_non_matrix_params = json_get<bool>(j, "optimize_non_matrix_params", true, w);
  return a;
}

}  // namespace

ModelConfig ModelConfig::from_json(const Json& in) {
  // The paper's appendix lists configs as {"params": {...}} wrapping the tcnn objects.
  const Json& j = (in.contains("params") && in.at("params").is_object() && !in.contains("encoding"))
                      ? in.at("params")
                      : (in.contains("model") && !in.contains("encoding") ? in.at("model") : in);
  if (!j.is_object()) fail("config: expected a JSON object");
  if (!j.contains("encoding")) fail("config: missing 'encoding' object");
  if (!j.contains("network")) fail("config: missing 'network' object");
  ModelConfig c;
  c.encoding = parse_encoding_config(j.at("encoding"));
  c.network = parse_network(j.at("network"));
  c.loss = parse_loss(j.value("loss", Json::object()));
  Json opt = j.value("optimizer", Json::object());
  if (!opt.is_object()) fail("config: 'optimizer' must be an object");
  if (iequals(opt.value("otype", std::string("Adam")), "ExponentialDecay")) {
    const char* w = "optimizer";
    c.decay.enabled = true;
    c.decay.decay_base = json_get<float>(opt, "decay_base", 0.1f, w);
    c.decay.decay_start = json_get<uint32_t>(opt, "decay_start", 10000u, w);
    c.decay.decay_interval = json_get<uint32_t>(opt, "decay_interval", 10000u, w);
    c.decay.decay_end = json_get<uint32_t>(opt, "decay_end", 10000000u, w);
    if (c.decay.decay_interval == 0) fail("optimizer: decay_interval must be positive");
    c.adam = parse_adam(opt.value("nested", Json::object()));
  } else {
    c.adam = parse_adam(opt);
  }
  return c;
}

const char* activation_name(Activation a) {
  switch (a) {
    case Activation::None: return "None";
    case Activation::ReLU: return "ReLU";
    case Activation::Exponential: return "Exponential";
    case Activation::Sine: return "Sine";
    case Activation::Sigmoid: return "Sigmoid";
    case Activation::Squareplus: return "Squareplus";
    case Activation::Softplus: return "Softplus";
  }
  return "?";
}

const char* loss_name(LossType l) {
  switch (l) {
    case LossType::L1: return "L1";
    case LossType::L2: return "L2";
    case LossType::RelativeL2: return "RelativeL2";
    case LossType::RelativeL1: return "RelativeL1";
  }
  return "?";
}

Json ModelConfig::to_json() const {
  const Json enc = make_encoding(encoding)->to_json();
  Json net = {{"otype", network.fully_fused ? "FullyFusedMLP" : "CutlassMLP"},
              {"activation", activation_name(network.activation)},
              {"output_activation", activation_name(network.output_activation)},
              {"n_neurons", network.n_neurons},
              {"n_hidden_layers", network.n_hidden_layers}};
  Json adam_j = {{"otype", "Adam"},
                 {"learning_rate", adam.learning_rate},
                 {"beta1", adam.beta1},
                 {"beta2", adam.beta2},
                 {"epsilon", adam.epsilon},
                 {"l2_reg", adam.l2_reg},
                 {"relative_decay", adam.relative_decay},
                 {"absolute_decay", adam.absolute_decay},
                 {"adabound", adam.adabound},
                 {"non_matrix_learning_rate_factor", adam.non_matrix_learning_rate_factor},
                 {"optimize_matrix_params", adam.optimize_matrix_params},
                 {"optimize_non_matrix_params", adam.optimize_non_matrix_params}};
  Json opt = adam_j;
  if (decay.enabled)
    opt = {{"otype", "ExponentialDecay"},
           {"decay_base", decay.decay_base},
           {"decay_start", decay.decay_start},
           {"decay_interval", decay.decay_interval},
           {"decay_end", decay.decay_end},
           {"nested", adam_j}};
  return {{"encoding", enc}, {"network", net}, {"loss", {{"otype", loss_name(loss)}}}, {"optimizer", opt}};
}

namespace {
Json paper_optimizer() {
  return Json::parse(R"({"otype":"ExponentialDecay","decay_start":2000,"decay_interval":1000,"decay_base":0.99,
    "nested":{"otype":"Adam","learning_rate":0.005,"beta1":0.9,"beta2":0.999,"epsilon":1e-15,"l2_reg":1e-6}})");
}
}  // namespace

bool is_preset(const std::string& name) {
  std::string l = to_lower(name);
  return l == "auto" || l == "paper" || l == "small" || l == "tiny";
}

const char* preset_names() { return "auto, paper, small"; }

Json preset_config(const std::string& name) {
  std::string l = to_lower(name);
  Json c;
  c["optimizer"] = paper_optimizer();
  c["loss"] = {{"otype", "L1"}};
  if (l == "paper" || l == "auto") {  // auto: the paper's network, which front ends may size (session.h)
    c["encoding"] = {{"otype", "HashGrid"}, {"n_levels", 8}, {"n_features_per_level", 8},
                     {"log2_hashmap_size", 19}, {"base_resolution", 4}, {"per_level_scale", 2.0}};
    c["network"] = {{"otype", "FullyFusedMLP"}, {"activation", "ReLU"}, {"output_activation", "None"},
                    {"n_neurons", 64}, {"n_hidden_layers", 4}};
  } else if (l == "small") {
    c["encoding"] = {{"otype", "HashGrid"}, {"n_levels", 4}, {"n_features_per_level", 2},
                     {"log2_hashmap_size", 16}, {"base_resolution", 4}, {"per_level_scale", 2.0}};
    c["network"] = {{"otype", "FullyFusedMLP"}, {"activation", "ReLU"}, {"output_activation", "None"},
                    {"n_neurons", 16}, {"n_hidden_layers", 2}};
  } else if (l == "tiny") {
    c["encoding"] = {{"otype", "HashGrid"}, {"n_levels", 3}, {"n_features_per_level", 2},
                     {"log2_hashmap_size", 10}, {"base_resolution", 4}, {"per_level_scale", 2.0}};
    c["network"] = {{"otype", "FullyFusedMLP"}, {"activation", "ReLU"}, {"output_activation", "None"},
                    {"n_neurons", 16}, {"n_hidden_layers", 2}};
  } else {
    fail("unknown preset '{}' (allowed: {})", name, preset_names());
  }
  return c;
}

ModelConfig load_config(const std::string& preset_or_path) {
  if (is_preset(preset_or_path)) return ModelConfig::from_json(preset_config(preset_or_path));
  if (!file_exists(preset_or_path))
    fail("--config '{}' is neither a preset ({}) nor an existing file", preset_or_path, preset_names());
  return ModelConfig::from_json(parse_json_file(preset_or_path));
}

Precision parse_precision(const std::string& name) {
  if (name == "auto") return kernels::bf16_preferred() ? Precision::BF16 : Precision::FP32;
  if (name == "fp32") return Precision::FP32;
  if (name != "bf16") fail("unknown precision '{}' (allowed: auto, fp32, bf16)", name);
  if (!kernels::bf16_supported()) fail("precision bf16 needs a CPU with AVX512-BF16 (this one has none); use fp32");
  return Precision::BF16;
}

const char* precision_name(Precision p) { return p == Precision::BF16 ? "bf16" : "fp32"; }

}  // namespace vnr
