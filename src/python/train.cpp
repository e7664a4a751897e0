// vnr.train: the CLI's training session (open_training_session) over a numpy array, a vnr.Volume or a
// volume file, run with the GIL released; the step callback takes the GIL to report progress, check
// for Ctrl-C and let the caller stop.
#include "bindings.h"
#include "vnr/error.h"
#include "vnr/threads.h"

namespace vnr::py {

namespace {

struct TrainArgs {
  pyb::object volume, config, callback;
  std::optional<int64_t> steps;
  std::optional<double> seconds, target_ratio;
  uint32_t seed = TrainingSetup{}.seed;
  std::string device, sampler, precision;
  int64_t batch = 65536;
  int macrocell_size = 16;
  std::optional<int> threads;
  bool verbose = false;
  std::optional<double> target_psnr, bits_per_param, qat_fraction, max_error, max_rel_error, cooldown, rate_weight;
  std::string residuals = "auto";
  bool learn_steps = false;
};

// What happened in the step callback that the session must not see as its own error.
struct CallbackState {
  pyb::object callback;
  std::optional<pyb::error_already_set> error;  // the callback raised: re-raised after the run
  bool interrupted = false;                      // Ctrl-C (KeyboardInterrupt), a clean stop
};

void on_step(TrainingSession& session, CallbackState& st, const TrainingProgress& p) {
  pyb::gil_scoped_acquire gil;
  if (PyErr_CheckSignals() != 0) {
    pyb::error_already_set e;
    if (e.matches(PyExc_KeyboardInterrupt)) st.interrupted = true;
    else st.error = std::move(e);
    session.request_stop();
    return;
  }
  if (st.callback.is_none()) return;
  try {
    pyb::object r = st.callback(p.step, p.loss, p.samples_per_second);
    if (!r.is_none() && !r.cast<bool>()) session.request_stop();
  } catch (pyb::error_already_set& e) {
    if (e.matches(PyExc_KeyboardInterrupt)) st.interrupted = true;
    else st.error = std::move(e);
    session.request_stop();
  }
}

// The library's TrainingSetup from the keyword arguments (TrainingSetup::from_json: its defaults for what
// is not given, its checks and messages); the volume is set by opener_of.
TrainingSetup setup_of(const TrainArgs& a) {
  Json j = {{"seed", a.seed},       {"device", a.device},     {"precision", a.precision}, {"batch", a.batch},
            {"macrocell_size", a.macrocell_size}, {"residuals", a.residuals}, {"sampler", a.sampler}};
  auto put = [&j](const char* key, const auto& value) {
    if (value) j[key] = *value;
  };
  put("steps", a.steps);
  put("target_ratio", a.target_ratio);
  put("target_psnr", a.target_psnr);
  put("bits_per_param", a.bits_per_param);
  put("qat_fraction", a.qat_fraction);
  put("rate_weight", a.rate_weight);
  if (a.learn_steps) j["learn_steps"] = true;
  put("cooldown", a.cooldown);
  put("max_error", a.max_error);
  put("max_rel_error", a.max_rel_error);
  if (a.seconds && *a.seconds <= 0) fail("seconds must be positive, got {}", *a.seconds);
  if (pyb::isinstance<pyb::dict>(a.config))
    j["config"] = Json::parse(pyb::str(pyb::module_::import("json").attr("dumps")(a.config)).cast<std::string>());
  else if (pyb::isinstance<pyb::str>(a.config))
    j["config"] = a.config.cast<std::string>();
  else
    j["config"] = pyb::str(pyb::module_::import("os").attr("fspath")(a.config)).cast<std::string>();
  TrainingSetup s = TrainingSetup::from_json(j);
  if (!s.config_json && !is_preset(s.config)) require_file(s.config, "config");
  return s;
}

// Opens sessions for a setup over the volume argument: a path (read by the library) or a volume in memory
// (shared, not copied). --target-psnr's search opens several.
SessionOpener opener_of(const TrainArgs& a, TrainingSetup& s, const MessageFn& say) {
  if (pyb::isinstance<pyb::str>(a.volume) || pyb::hasattr(a.volume, "__fspath__")) {
    s.volume = pyb::str(pyb::module_::import("os").attr("fspath")(a.volume)).cast<std::string>();
    require_file(s.volume, "volume");
    return [say](const TrainingSetup& setup) { return open_training_session(setup, say); };
  }
  std::shared_ptr<const Volume> vol;
  if (pyb::isinstance<Volume>(a.volume)) {
    vol = a.volume.cast<std::shared_ptr<Volume>>();  // shared, not copied
  } else {
    pyb::array arr = pyb::array::ensure(a.volume);
    if (!arr) fail("volume must be a numpy array, a vnr.Volume or a path");
    vol = std::make_shared<const Volume>(volume_from_numpy(arr, std::nullopt, std::nullopt));
  }
  s.volume = "array";
  return [say, vol](const TrainingSetup& setup) { return open_training_session(setup, vol, say); };
}

ModelPtr train(const TrainArgs& a) {
  TrainingSetup setup = setup_of(a);
  if (a.threads) set_num_threads(*a.threads);
  std::vector<std::string> lines;
  std::mutex lines_mutex;
  MessageFn say = [&](const std::string& line) {
    std::lock_guard lock(lines_mutex);
    lines.push_back(line);
  };
  const SessionOpener open = opener_of(a, setup, say);
  const int64_t steps = planned_steps(a.steps.value_or(-1), a.seconds.value_or(0));
  CallbackState st;
  st.callback = a.callback;
  auto attach = [&](TrainingSession& s) { s.add_step_callback([&](const TrainingProgress& p) { on_step(s, st, p); }); };
  std::unique_ptr<TrainingSession> session;
  bool psnr_short = false;  // target_psnr alone, and no size reached it
  {
    pyb::gil_scoped_release release;
    TargetTraining trained = train_for_targets(setup, steps, a.seconds.value_or(0), open, say, attach);
    psnr_short = trained.search && !trained.search->reached && !trained.search->interrupted;
    session = std::move(trained.session);
    session->finish({.evaluate = false, .save = false});  // quantized (compact), residuals attached (error bound)
  }
  if (a.verbose)
    for (const std::string& l : lines) pyb::print(l, pyb::arg("file") = pyb::module_::import("sys").attr("stderr"));
  if (st.error) throw std::move(*st.error);
  TrainingSession& s = *session;
  if (psnr_short)
    PyErr_WarnFormat(PyExc_RuntimeWarning, 1,
                     "vnr.train: no model up to 1/4 of the volume reaches target_psnr=%S on held-back voxels; "
                     "returning the largest (train longer or give a larger config)",
                     pyb::float_(setup.target_psnr).ptr());
  if (st.interrupted)
    PyErr_WarnFormat(PyExc_RuntimeWarning, 1, "vnr.train interrupted after %lld steps: returning the model so far",
                     (long long)s.steps_done());
  auto h = std::make_shared<ModelHolder>();
  h->model = std::move(s.model());
  // decode() then equals `vnr decode` of the CLI's model, and save/load is lossless.
  round_params_to_stored(h->model);
  set_inference_precision(h->model, parse_precision("auto"));
  session.reset();
  return h;
}

const char* kTrainDoc = R"(Trains a neural representation of a volume and returns the vnr.Model.

volume: a 3-D numpy array (as vnr.Volume.from_numpy takes it), a vnr.Volume (shared, not copied) or a
path of any volume the CLI reads. Given an array, vnr's normalised float32 copy lives only while train
runs (a vnr.Volume keeps its own until it is released). The session is `vnr train`'s: the same config, seed, batch and
thread count give the same model as `vnr train ... --seed S --threads T`; its parameters are rounded
to fp16 as the model file stores them (so decode() equals `vnr decode` of that file).
config: "auto" (the paper's network; with max_error/max_rel_error alone, sized for the bound), a preset
("paper", "small"), a tiny-cuda-nn config dict, or a JSON file path.
steps / seconds: stop after this many steps or seconds of training (default: 1000 steps).
seed: 1337 by default, as the CLI's --seed (TrainingSetup's default).
device: "auto" (a visible GPU, else the CPU), "cpu" or "cuda".
sampler: "incore" for arrays and volumes in memory; a path may also use "outofcore" or "mmap".
target_ratio: a compact model (quantized, entropy-coded parameters) of 1/R of the volume's bytes, as
`vnr train --target-ratio` writes it (bits_per_param sizes its grid; the last qat_fraction of the steps
train quantization-aware; rate_weight > 0 adds the grid's bits to their loss, as --rate-weight;
learn_steps=True trains the grid levels' quantization steps in that part too, as --learn-steps;
residuals="auto" spends part of the file on residuals where that decodes better, as --residuals: decode()
applies them, sample() and render() see the network alone; "off" keeps the whole file for the network).
target_psnr: the smallest compact model whose PSNR on held-back voxels reaches this (dB): several
sizes are trained (each for steps/seconds); with target_ratio, one model quantized as coarsely as
keeps it. max_error / max_rel_error: every voxel of decode() within this of the original (data units /
fraction of the value range): residuals of the network are kept in the model (docs/COMPRESSION.md).
cooldown: the last fraction of steps/seconds over which the learning rate falls linearly to 0 (default
0.2, as the CLI's --cooldown; 0 keeps tiny-cuda-nn's schedule exactly).
callback(step, loss, samples_per_second): called after each step (GPU: each step group); returning
False stops training. Ctrl-C stops training cleanly and returns the model trained so far (with a
RuntimeWarning). threads: CPU threads (vnr.set_num_threads); verbose: print the CLI's notes to stderr.)";

}  // namespace

void bind_train(pyb::module_& m) {
  m.def(
      "train",
      [](pyb::object volume, pyb::object config, std::optional<int64_t> steps, std::optional<double> seconds,
         uint32_t seed, const std::string& device, const std::string& sampler, std::optional<double> target_ratio,
         pyb::object callback, int64_t batch, const std::string& precision, int macrocell_size,
         std::optional<int> threads, bool verbose, std::optional<double> target_psnr,
         std::optional<double> bits_per_param, std::optional<double> qat_fraction, std::optional<double> max_error,
         std::optional<double> max_rel_error, std::optional<double> cooldown, std::optional<double> rate_weight,
         const std::string& residuals, bool learn_steps) {
        TrainArgs a{volume,   config,         callback,     steps,     seconds,      target_ratio,  seed,
                    device,   sampler,        precision,    batch,     macrocell_size, threads,      verbose,
                    target_psnr, bits_per_param, qat_fraction, max_error, max_rel_error, cooldown, rate_weight,
                    residuals, learn_steps};
        return train(a);
      },
      pyb::arg("volume"), pyb::arg("config") = "auto", pyb::arg("steps") = pyb::none(),
      pyb::arg("seconds") = pyb::none(), pyb::arg("seed") = TrainingSetup{}.seed, pyb::arg("device") = "auto",
      pyb::arg("sampler") = "incore", pyb::arg("target_ratio") = pyb::none(), pyb::arg("callback") = pyb::none(),
      pyb::kw_only(), pyb::arg("batch") = 65536, pyb::arg("precision") = "auto", pyb::arg("macrocell_size") = 16,
      pyb::arg("threads") = pyb::none(), pyb::arg("verbose") = false, pyb::arg("target_psnr") = pyb::none(),
      pyb::arg("bits_per_param") = pyb::none(), pyb::arg("qat_fraction") = pyb::none(),
      pyb::arg("max_error") = pyb::none(), pyb::arg("max_rel_error") = pyb::none(),
      pyb::arg("cooldown") = pyb::none(), pyb::arg("rate_weight") = pyb::none(),
      pyb::arg("residuals") = "auto", pyb::arg("learn_steps") = false, kTrainDoc);
}

}  // namespace vnr::py
