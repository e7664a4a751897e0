// The _vnr extension module: library errors become ValueError with the library's (the CLI's) message;
// each part of the API is bound in its own file.
#include "bindings.h"
#include "vnr/error.h"
#include "vnr/threads.h"
#include "vnr/version.h"

PYBIND11_MODULE(_vnr, m) {
  namespace py = vnr::py;
  m.doc() = "vnr's compiled core; import the `vnr` package instead.";
  pybind11::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const vnr::Error& e) {
      PyErr_SetString(PyExc_ValueError, e.what());
    }
  });
  m.attr("__version__") = vnr::version();
  m.def("set_num_threads", &vnr::set_num_threads, pybind11::arg("threads"),
        "Sets the CPU threads vnr uses (0: all cores), as the CLI's --threads does.");
  m.def("num_threads", &vnr::num_threads, "The CPU threads vnr uses.");
  py::bind_volume(m);
  py::bind_model(m);
  py::bind_train(m);
  py::bind_train_series(m);
  py::bind_render(m);
  py::bind_metrics(m);
}
