// open_training_session: from `vnr train`'s options to a running session (config, data, model size,
// device, backend).
#include "vnr/error.h"
#include "vnr/units.h"
#include "vnr/cuda/cuda.h"
#include "vnr/model_config.h"
#include "vnr/train/config_sizing.h"
#include "vnr/train/make_trainer.h"
#include "vnr/train/session.h"
#include <cmath>

namespace vnr {
std::unique_ptr<TrainingSession> make_training_session(Model& model, const Volume& volume, Device device,
                                                       const TrainOptions& options, int online_cell_size,
                                                       SessionOptions session) {
  if (!(model.dims == volume.dims))
    fail("the model represents {}x{}x{} voxels, the volume has {}x{}x{}", model.dims.x, model.dims.y, model.dims.z,
         volume.dims.x, volume.dims.y, volume.dims.z);
  return make_training_session(model, std::make_shared<InCoreSampler>(volume), &volume, device, options,
                               online_cell_size, std::move(session));
}

std::unique_ptr<TrainingSession> make_training_session(Model& model, std::shared_ptr<Sampler> sampler,
                                                       const Volume* in_memory, Device device,
                                                       const TrainOptions& options, int online_cell_size,
                                                       SessionOptions session, cuda::MlpPath mlp) {
  auto trainer = make_trainer(device, *model.net, std::move(sampler), in_memory, options, mlp);
  if (online_cell_size > 0) trainer->enable_online_ranges(in_memory ? in_memory->dims : model.dims, online_cell_size);
  return std::make_unique<TrainingSession>(model, std::move(trainer), std::move(session));
}

namespace {

// The setup's config: its JSON when given, else the preset or file named.
ModelConfig config_of(const TrainingSetup& s) {
  return s.config_json ? ModelConfig::from_json(*s.config_json) : load_config(s.config);
}

// open_training_session once the training data is open: model size, model, device, backend.
std::unique_ptr<TrainingSession> session_on_data(const TrainingSetup& s, ModelConfig config,
                                                 std::shared_ptr<TrainingData> data, const MessageFn& message) {
  auto say = [&](const std::string& line) {
    if (message) message(line);
  };
  if (data->hi == data->lo)
    say(fmt::format("note: the volume is constant ({:g}); it is represented as normalised 0", data->lo));
  if (s.session.error_bound.active()) {  // checked before training, not after it
    normalised_error_bound(s.session.error_bound, data->lo, data->hi, data->dtype);
    if (!data->vol) fail("an error bound (--max-error/--max-rel-error) needs the volume in memory (in-core sampler)");
    if (is_instantvnr_path(s.session.output))
      fail("'{}': instantvnr's format cannot hold error-bound residuals; save the model as .vnr", s.session.output);
  }
  std::string note;
  SessionOptions session_opts = s.session;
  double target_ratio = s.target_ratio;
  if (target_ratio <= 0 && s.target_psnr <= 0 && s.session.error_bound.active() && !s.config_json &&
      s.config == "auto") {
    const ResidualSplit split = bounded_network_split(
        *data->vol, data->source_bytes(), normalised_error_bound(s.session.error_bound, data->lo, data->hi, data->dtype),
        &note);
    say(note);
    target_ratio = split.network_ratio;
    if (split.small_network) config = load_config("small");
  }
  uint64_t file_bytes = 0;  // > 0: residuals fill the file to this size beside a smaller network
  if (s.target_ratio > 0 && s.target_psnr <= 0 && !s.session.error_bound.active() && s.residuals == "auto" &&
      data->vol && !is_instantvnr_path(s.session.output)) {
    const ResidualSplit split = residual_network_split(data->source_bytes(), data->dims.count(), s.target_ratio,
                                                       !s.config_json && s.config == "auto", &note);
    if (split.network_ratio > 0) {
      say(note);
      file_bytes = uint64_t(double(data->source_bytes()) / s.target_ratio);
      target_ratio = split.network_ratio;
      if (split.small_network) config = load_config("small");
    }
  }
  if (target_ratio > 0) {
    const uint64_t target = uint64_t(double(data->source_bytes()) / target_ratio);
    config = size_config_for_bytes(config, target, s.bits_per_param, &note);
    say(fmt::format("{} {:g}: {}", file_bytes ? "the network at ratio" : "--target-ratio", target_ratio, note));
    session_opts.compact.target_bytes = target;
    session_opts.compact.file_bytes = file_bytes;
  }
  session_opts.compact.target_psnr = s.target_psnr;
  session_opts.compact.qat_fraction = s.qat_fraction;
  session_opts.compact.rate_weight = s.rate_weight;
  session_opts.compact.learn_steps = s.learn_steps;
  if (data->out_of_core) {
    config = scale_grid_learning_rate(config, s.data.grid_lr_scale, *data->out_of_core, &note);
    if (!note.empty()) say(note);
  }
  Model model = create_model(config, data->dims, data->dtype, data->lo, data->hi, s.seed);
  Network& net = *model.net;
  if (target_ratio <= 0 && model.param_bytes() > data->source_bytes())
    say(fmt::format("note: the model ({}) is larger than the volume ({}); use --target-ratio R to compress",
                    human_bytes(double(model.param_bytes())), human_bytes(double(data->source_bytes()))));

  const DeviceChoice device = choose_training_device(s.device, net, data->dims, data->vol != nullptr, s.batch,
                                                     s.cpu_only_reason);
  if (!device.note.empty()) say("note: " + device.note);
  TrainOptions to{s.batch, s.seed};
  std::unique_ptr<Trainer> trainer;
  if (device.device == Device::Cuda) {
    if (s.precision != "auto")
      say(fmt::format("note: --precision {} applies to CPU training; the GPU trainer keeps its own arithmetic",
                      s.precision));
    trainer = make_trainer(Device::Cuda, net, data->sampler, data->vol ? &*data->vol : nullptr, to,
                           cuda::parse_mlp_path(s.mlp));
  } else {
    to.precision = resolve_training_precision(s.precision, net);
    trainer = make_trainer(Device::Cpu, net, data->sampler, nullptr, to);
  }
  if (s.macrocell_size > 0) trainer->enable_online_ranges(data->dims, s.macrocell_size);
  if (!trainer->device_summary().empty()) say("training on " + trainer->device_summary());
  SessionOptions so = session_opts;
  so.sampler_name = data->kind;
  return std::make_unique<TrainingSession>(std::move(model), std::move(data), std::move(trainer), so);
}

}  // namespace

std::unique_ptr<TrainingSession> open_training_session(const TrainingSetup& s, const MessageFn& message) {
  check_training_setup(s);
  ModelConfig config = config_of(s);
  const VolumeDesc desc = describe_volume(s.volume, s.raw);
  TrainingDataOptions dopt = s.data;
  if (dopt.memory_budget == 0) dopt.memory_budget = available_memory_bytes() / 2;
  dopt.seed = s.seed;
  dopt.steps = s.steps;
  auto data = std::make_shared<TrainingData>(open_training_data(s.volume, desc, s.load, dopt, message));
  return session_on_data(s, std::move(config), std::move(data), message);
}

std::unique_ptr<TrainingSession> open_training_session(const TrainingSetup& s, std::shared_ptr<const Volume> volume,
                                                       const MessageFn& message) {
  check_training_setup(s);
  if (!volume) fail("open_training_session: no volume given");
  if (!s.data.sampler.empty() && s.data.sampler != "incore")
    fail("a volume in memory is sampled in core; --sampler {} needs a volume file", s.data.sampler);
  ModelConfig config = config_of(s);
  const uint64_t budget = s.data.memory_budget ? s.data.memory_budget : available_memory_bytes() / 2;
  auto data = std::make_shared<TrainingData>(in_memory_training_data(s.volume, std::move(volume), budget, message));
  return session_on_data(s, std::move(config), std::move(data), message);
}

}  // namespace vnr
