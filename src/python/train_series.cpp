// vnr.train_series: a time series trained into a directory of models by the library's run_series (what
// `vnr train SERIES --timesteps` runs), with the GIL released; Ctrl-C stops after the current step (that
// timestep's model is still saved) and the report is returned.
#include "bindings.h"
#include "vnr/error.h"
#include "vnr/threads.h"
#include "vnr/trainer.h"

namespace vnr::py {

namespace {

const char* kTrainSeriesDoc = R"(Trains a time series into a directory of models; returns the report (a dict).

volume: the path of a time series the CLI reads (a 4-D sidecar, a sidecar listing one file per timestep,
a scene with several dataSource entries). output_dir: the models go to output_dir/t0000.vnr, ... (the
timestep's index), each written as soon as it is done, and the report to output_dir/series.json (or
report), rewritten after each model, as `vnr train VOLUME --timesteps ... -o DIR` does.
timesteps: "all", "A-B" or "A,B,C". One model per timestep, warm-started from the previous one, trained
steps or seconds each (default 1000 steps); continuous=True trains one network across the timesteps,
switch_every steps each, and saves a model per timestep. target_ratio / max_error / max_rel_error:
compact or error-bounded models per timestep. The other keywords are vnr.train's. Ctrl-C stops after the
current step: that timestep's model is saved and the report marked interrupted.)";

Json series_report(const pyb::kwargs& kw, const std::string& volume, const std::string& output_dir,
                   const std::string& timesteps, bool continuous, int64_t switch_every, std::optional<double> seconds,
                   bool ssim, const std::string& report, std::optional<int> threads) {
  SeriesRunSetup s;
  Json j = Json::object();
  for (const auto& [key, value] : kw) {  // vnr.train's keywords, checked by TrainingSetup::from_json
    const pyb::object v = pyb::hasattr(value, "__fspath__") ? pyb::module_::import("os").attr("fspath")(value)
                                                            : pyb::reinterpret_borrow<pyb::object>(value);
    j[pyb::str(key).cast<std::string>()] =
        Json::parse(pyb::str(pyb::module_::import("json").attr("dumps")(v)).cast<std::string>());
  }
  j["volume"] = volume;
  j["output"] = output_dir;
  s.train = TrainingSetup::from_json(j);
  require_file(s.train.volume, "volume");
  s.seconds = seconds.value_or(0);
  s.timesteps = timesteps;
  s.continuous = continuous;
  s.switch_every = switch_every;
  s.report = report;
  s.ssim = ssim;
  if (threads) set_num_threads(*threads);
  bool interrupted = false;
  SeriesRunCallbacks cb;
  cb.hooks.stop = [&] {
    pyb::gil_scoped_acquire gil;
    if (PyErr_CheckSignals() != 0) {
      pyb::error_already_set e;
      if (!e.matches(PyExc_KeyboardInterrupt)) throw std::move(e);
      interrupted = true;
    }
    return interrupted;
  };
  SeriesRunResult r;
  {
    pyb::gil_scoped_release release;
    r = run_series(s, cb, [](const std::string& key) { return key; });  // errors name the keywords
  }
  if (interrupted)
    PyErr_WarnFormat(PyExc_RuntimeWarning, 1, "vnr.train_series interrupted: the models so far are in %s",
                     output_dir.c_str());
  return r.report;
}

}  // namespace

void bind_train_series(pyb::module_& m) {
  m.def(
      "train_series",
      [](pyb::object volume, pyb::object output_dir, const std::string& timesteps, bool continuous,
         int64_t switch_every, std::optional<double> seconds, bool ssim, pyb::object report,
         std::optional<int> threads, const pyb::kwargs& kw) {
        const auto path = [](const pyb::object& p) {
          return pyb::str(pyb::module_::import("os").attr("fspath")(p)).cast<std::string>();
        };
        const Json rep = series_report(kw, path(volume), path(output_dir), timesteps, continuous, switch_every, seconds,
                                       ssim, report.is_none() ? std::string() : path(report), threads);
        return pyb::module_::import("json").attr("loads")(rep.dump());
      },
      pyb::arg("volume"), pyb::arg("output_dir"), pyb::arg("timesteps") = "all", pyb::kw_only(),
      pyb::arg("continuous") = false, pyb::arg("switch_every") = 0, pyb::arg("seconds") = pyb::none(),
      pyb::arg("ssim") = true, pyb::arg("report") = pyb::none(), pyb::arg("threads") = pyb::none(), kTrainSeriesDoc);
}

}  // namespace vnr::py
