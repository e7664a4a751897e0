// vnr.Model: a trained network and the volume it represents; decodes and point queries return numpy
// arrays in original units, computed with the GIL released on all cores (or the GPU).
#include <algorithm>
#include "bindings.h"
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/bricks.h"
#include "vnr/volume_writer.h"

namespace vnr::py {

ModelQuery& ModelHolder::query_on(Device device) {
  if (!query || query->device() != device) {
    query.reset();
    query = std::make_unique<ModelQuery>(model, device);
  }
  return *query;
}

namespace {

// Points converted to interleaved float32 per batch when the input is not already that.
constexpr int64_t kPointBatch = int64_t(1) << 20;

pyb::array decode(ModelHolder& h, const pyb::object& shape, const std::string& dtype_name,
                  const std::string& device) {
  const Int3 dims = shape.is_none() ? h.model.dims : dims_of_shape(pyb::tuple(shape));
  const DType out_t = dtype_name == "source" ? h.model.source_dtype : parse_dtype(dtype_name);
  const Device dev = parse_device(device);
  pyb::array out(numpy_dtype(out_t), shape_of(dims));
  void* dst = out.mutable_data();
  pyb::gil_scoped_release release;
  std::lock_guard lock(h.mutex);
  ModelQuery& q = h.query_on(dev);
  if (out_t == DType::Float32) {  // straight into the array
    q.slab(dims, 0, dims.z, static_cast<float*>(dst), ValueUnits::Original);
    return out;
  }
  const int64_t plane = dims.x * dims.y;
  q.for_each_slab(dims, [&](int64_t z0, int64_t z1, const float* values) {
    // `vnr decode`'s conversion (little-endian bytes: the host's order on every platform vnr builds for)
    store_values(out_t, values, plane * (z1 - z0), static_cast<unsigned char*>(dst) + z0 * plane * int64_t(dtype_size(out_t)));
  });
  return out;
}

// Interleaved x, y, z of n points from rows [b, e) of a (n, 3) array, checked to lie in [0, 1].
template <typename T>
void gather_points(const pyb::array& a, int64_t b, int64_t e, float* xyz) {
  auto r = a.unchecked<T, 2>();
  for (int64_t i = b; i < e; ++i)
    for (int k = 0; k < 3; ++k) xyz[3 * (i - b) + k] = float(r(i, k));
}

pyb::array_t<float> sample(ModelHolder& h, const pyb::array& points, const std::string& device) {
  if (points.ndim() != 2 || points.shape(1) != 3) fail("points must be an (N, 3) array of x, y, z in [0, 1]");
  const char kind = points.dtype().kind();
  const int size = int(points.dtype().itemsize());
  if (kind != 'f' || (size != 4 && size != 8)) fail("points must be float32 or float64, got {}", pyb::str(static_cast<pyb::handle>(points.dtype())).cast<std::string>());
  const Device dev = parse_device(device);
  const int64_t n = points.shape(0);
  pyb::array_t<float> out(n);
  float* dst = out.mutable_data();
  const bool direct = size == 4 && (points.flags() & pyb::array::c_style) && points.dtype().byteorder() != '>';
  const auto* src = static_cast<const float*>(points.data());
  pyb::gil_scoped_release release;
  std::lock_guard lock(h.mutex);
  ModelQuery& q = h.query_on(dev);
  if (direct) {  // the caller's memory as it is
    check_unit_points(src, n, 0);
    q.points(src, n, dst, ValueUnits::Original);
    return out;
  }
  std::vector<float> xyz(size_t(3 * std::min(n, kPointBatch)));
  for (int64_t b = 0; b < n; b += kPointBatch) {
    const int64_t e = std::min(n, b + kPointBatch);
    {
      pyb::gil_scoped_acquire gil;  // numpy accessors of a strided or byte-swapped array
      if (size == 4) gather_points<float>(points, b, e, xyz.data());
      else gather_points<double>(points, b, e, xyz.data());
    }
    check_unit_points(xyz.data(), e - b, b);
    q.points(xyz.data(), e - b, dst + b, ValueUnits::Original);
  }
  return out;
}

pyb::object json_to_python(const Json& j) { return pyb::module_::import("json").attr("loads")(j.dump()); }

}  // namespace

void bind_model(pyb::module_& m) {
  pyb::class_<ModelHolder, ModelPtr> c(m, "Model", R"(A trained neural representation of a volume: the network and the volume's dims, value range
and source dtype. Made by vnr.train or vnr.Model.load; decode() and sample() give values in the
original units of the volume. Arrays are (nz, ny, nx), x fastest (see vnr.Volume).)");
  c.def_static(
      "load",
      [](const std::string& path) {
        require_file(path, "model");
        auto h = std::make_shared<ModelHolder>();
        pyb::gil_scoped_release release;
        h->model = load_model(path);
        set_inference_precision(h->model, parse_precision("auto"));
        h->file_bytes = model_file_bytes(path);  // a multi-brick directory: its files together
        return h;
      },
      pyb::arg("path"), "Loads a model file (.vnr, or instantvnr's BSON), or a multi-brick model directory (`vnr train --bricks`), as `vnr decode` does.");
  c.def(
      "save",
      [](ModelHolder& h, const std::string& path) {
        pyb::gil_scoped_release release;
        std::lock_guard lock(h.mutex);
        save_model(path, h.model);
        h.file_bytes = file_size(path);
      },
      pyb::arg("path"), "Writes the model (.vnr; .bson/.json: instantvnr's BSON), atomically.");
  c.def("decode", &decode, pyb::arg("shape") = pyb::none(), pyb::arg("dtype") = "float32", pyb::arg("device") = "auto",
        R"(The volume decoded at voxel centres, in original units, as a numpy array of shape (nz, ny, nx).

shape: the output's (nz, ny, nx) (default: the trained volume's); dtype: "float32", "source" (the
trained volume's dtype, integers rounded to nearest and clamped, as `vnr decode --dtype source`) or a
dtype name; device: "auto", "cpu" or "cuda". The GIL is released while it runs.)");
  c.def(
      "decode_to_file",
      [](ModelHolder& h, const std::string& path, const pyb::object& shape, const std::string& dtype_name,
         const std::string& device, bool force) {
        const Int3 dims = shape.is_none() ? h.model.dims : dims_of_shape(pyb::tuple(shape));
        const DType out_t = dtype_name == "source" ? h.model.source_dtype : parse_dtype(dtype_name);
        const Device dev = parse_device(device);
        if (!force)
          for (const std::string& f : volume_output_files(path))
            if (file_exists(f)) fail("'{}' exists (force=True replaces it)", f);
        pyb::gil_scoped_release release;
        std::lock_guard lock(h.mutex);
        h.query_on(dev).decode_to_file(path, dims, out_t);
      },
      pyb::arg("path"), pyb::arg("shape") = pyb::none(), pyb::arg("dtype") = "float32", pyb::arg("device") = "auto",
      pyb::arg("force") = false,
      R"(Writes what `vnr decode` writes: the volume decoded at `shape` (nz, ny, nx; default the trained
volume's) into path (OUT.raw with its OUT.json sidecar, or OUT.nrrd), atomically, in slabs of about
16 M voxels, so a volume larger than memory decodes too. dtype and device as decode(); force=True
replaces existing files. The GIL is released while it runs.)");
  c.def("sample", &sample, pyb::arg("points"), pyb::arg("device") = "auto",
        R"(The model's values (original units, float32, shape (N,)) at N points given as an (N, 3) float32 or
float64 array of normalised x, y, z in [0, 1] (voxel i's centre is (i + 0.5) / n). Runs in batches on
all cores (or the GPU) with the GIL released; a C-ordered float32 array is used without a copy.)");
  c.def_property_readonly("config", [](const ModelHolder& h) { return json_to_python(model_config(h.model).to_json()); },
                          "The network's tiny-cuda-nn config as a dict.");
  c.def_property_readonly("n_params", [](const ModelHolder& h) { return h.model.n_params(); },
                          "Number of parameters (stored as fp16).");
  c.def_property_readonly(
      "compression_ratio", [](const ModelHolder& h) { return compression_ratio(h.model, h.file_bytes); },
      "Source volume bytes / model bytes: of its file once saved or loaded (as `vnr info`), else of the fp16 "
      "parameters.");
  c.def_property_readonly("value_range", [](const ModelHolder& h) { return std::make_pair(h.model.lo, h.model.hi); },
                          "(lo, hi): the original units of normalised 0 and 1.");
  c.def_property_readonly("dims", [](const ModelHolder& h) { return std::make_tuple(h.model.dims.x, h.model.dims.y, h.model.dims.z); },
                          "Voxels per axis (x, y, z) of the volume it represents.");
  c.def_property_readonly("shape", [](const ModelHolder& h) { return pyb::tuple(pyb::cast(shape_of(h.model.dims))); },
                          "The numpy shape (nz, ny, nx) of decode()'s default output.");
  c.def_property_readonly("source_dtype", [](const ModelHolder& h) { return numpy_dtype(h.model.source_dtype); },
                          "The dtype of the volume it was trained on.");
  c.def_property_readonly("training", [](const ModelHolder& h) { return json_to_python(h.model.training); },
                          "The training record (steps, seconds, loss, seed, device, ...) as a dict.");
  c.def("__repr__", [](const ModelHolder& h) {
    const Model& md = h.model;
    return fmt::format("vnr.Model({}x{}x{} {}, {} params, value_range=({:g}, {:g}))", md.dims.x, md.dims.y, md.dims.z,
                       dtype_name(md.source_dtype), md.n_params(), md.lo, md.hi);
  });
}

}  // namespace vnr::py
