#pragma once
// Shared by the _vnr binding files: the holders of the library's objects and the conversions between
// numpy and vnr (axis order, dtypes, errors).
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include "vnr/vnr.h"

namespace vnr::py {

namespace pyb = pybind11;

// A model shared between Python objects (and the queries made on it). The query of the last device
// used is kept (on the GPU it holds the network's copy); `mutex` serialises queries, which run with
// the GIL released.
struct ModelHolder {
  Model model;
  std::unique_ptr<ModelQuery> query;
  std::mutex mutex;
  uint64_t file_bytes = 0;  // the size of the file it was loaded from or saved to (0: none)
  ModelQuery& query_on(Device device);
};
using ModelPtr = std::shared_ptr<ModelHolder>;
using VolumePtr = std::shared_ptr<const Volume>;

// Raises FileNotFoundError (with the CLI's wording) unless `path` names an existing file.
void require_file(const std::string& path, const char* what);
// "auto" | "cpu" | "cuda" -> a device (vnr::Error, i.e. ValueError, for anything else or a missing GPU).
Device parse_device(const std::string& name);
// The numpy dtype of a vnr dtype and back (ValueError for a dtype vnr does not hold).
pyb::dtype numpy_dtype(DType t);
DType vnr_dtype(const pyb::dtype& dt);
// A (nz, ny, nx) C-order or (nx, ny, nz) Fortran-order array as vnr dims (x fastest in memory), or
// nullopt when its memory is not laid out that way (it is then copied by the caller).
std::optional<Int3> dims_of_layout(const pyb::array& a);
// numpy's shape (nz, ny, nx) of dims (x, y, z) and back, checking each extent.
std::vector<pyb::ssize_t> shape_of(Int3 dims);
Int3 dims_of_shape(const pyb::tuple& shape);
// Normalises an array as open_volume would read a raw file of its dtype (no copy of a C- or
// Fortran-ordered array; other layouts are copied once). Non-finite values: ValueError.
Volume volume_from_numpy(const pyb::array& array, std::optional<double> lo, std::optional<double> hi,
                         NonFinitePolicy policy = NonFinitePolicy::Error);

void bind_volume(pyb::module_& m);
void bind_model(pyb::module_& m);
void bind_train(pyb::module_& m);
void bind_train_series(pyb::module_& m);
void bind_render(pyb::module_& m);
void bind_metrics(pyb::module_& m);

}  // namespace vnr::py
