// vnr.Volume: numpy arrays and volume files as vnr volumes (normalised float32, x fastest), and the
// conversions every binding file shares.
#include "bindings.h"
#include "vnr/error.h"
#include "vnr/fileio.h"

namespace vnr::py {

void require_file(const std::string& path, const char* what) {
  if (file_exists(path)) return;
  // "file.h5:/group/dataset" style descriptors: the file is the part before the last ':'.
  const size_t colon = path.rfind(':');
  if (colon != std::string::npos && colon > 0 && file_exists(path.substr(0, colon))) return;
  PyErr_SetString(PyExc_FileNotFoundError, fmt::format("cannot open {} '{}': no such file", what, path).c_str());
  throw pyb::error_already_set();
}

Device parse_device(const std::string& name) {
  if (name != "auto" && name != "cpu" && name != "cuda")
    fail("unknown device '{}' (allowed: auto, cpu, cuda)", name);
  return cuda::resolve_device(name);
}

pyb::dtype numpy_dtype(DType t) { return pyb::dtype(std::string(dtype_name(t))); }

DType vnr_dtype(const pyb::dtype& dt) {
  const char kind = dt.kind();
  const int size = int(dt.itemsize());
  if (kind == 'i' && size == 1) return DType::Int8;
  if (kind == 'u' && size == 1) return DType::UInt8;
  if (kind == 'i' && size == 2) return DType::Int16;
  if (kind == 'u' && size == 2) return DType::UInt16;
  if (kind == 'i' && size == 4) return DType::Int32;
  if (kind == 'u' && size == 4) return DType::UInt32;
  if (kind == 'f' && size == 4) return DType::Float32;
  if (kind == 'f' && size == 8) return DType::Float64;
  fail("unsupported dtype {} (allowed: int8, uint8, int16, uint16, int32, uint32, float32, float64)",
       pyb::str(static_cast<const pyb::handle&>(dt)).cast<std::string>());
}

std::vector<pyb::ssize_t> shape_of(Int3 dims) { return {pyb::ssize_t(dims.z), pyb::ssize_t(dims.y), pyb::ssize_t(dims.x)}; }

Int3 dims_of_shape(const pyb::tuple& shape) {
  if (shape.size() != 3) fail("shape must be (nz, ny, nx), got {} values", shape.size());
  Int3 d{shape[2].cast<int64_t>(), shape[1].cast<int64_t>(), shape[0].cast<int64_t>()};
  if (d.x < 1 || d.y < 1 || d.z < 1) fail("shape must be positive, got ({}, {}, {})", d.z, d.y, d.x);
  return d;
}

std::optional<Int3> dims_of_layout(const pyb::array& a) {
  const int flags = pyb::detail::array_proxy(a.ptr())->flags;
  if (flags & pyb::detail::npy_api::NPY_ARRAY_C_CONTIGUOUS_) return Int3{a.shape(2), a.shape(1), a.shape(0)};
  if (flags & pyb::detail::npy_api::NPY_ARRAY_F_CONTIGUOUS_) return Int3{a.shape(0), a.shape(1), a.shape(2)};
  return std::nullopt;
}

namespace {

void check_volume_array(const pyb::array& a) {
  if (a.ndim() != 3) {
    std::string shape;
    for (pyb::ssize_t i = 0; i < a.ndim(); ++i) shape += (i ? ", " : "") + std::to_string(a.shape(i));
    fail("a volume is a 3-D array (nz, ny, nx), got shape ({})", shape);
  }
  if (a.size() == 0) fail("a volume needs at least one voxel, got shape ({}, {}, {})", a.shape(0), a.shape(1), a.shape(2));
}

bool big_endian_of(const pyb::dtype& dt) {
  const char order = dt.byteorder();
  if (order == '>') return true;
  if (order == '<') return false;
  return std::endian::native == std::endian::big;  // '=' or '|' (native, or single bytes)
}

// A read-only numpy view of count floats owned by `owner` (kept alive by the array).
template <typename Owner>
pyb::array_t<float> view_of_floats(const float* data, Int3 dims, std::shared_ptr<Owner> owner) {
  auto* keep = new std::shared_ptr<Owner>(std::move(owner));
  pyb::capsule base(keep, [](void* p) { delete static_cast<std::shared_ptr<Owner>*>(p); });
  pyb::array_t<float> out(shape_of(dims), data, base);
  pyb::detail::array_proxy(out.ptr())->flags &= ~pyb::detail::npy_api::NPY_ARRAY_WRITEABLE_;
  return out;
}

const char* kVolumeDoc = R"(A scalar volume in memory, as vnr holds it: values normalised to [0, 1] with the value range
(lo, hi) in original units and the source dtype recorded.

Axis convention: a numpy array of shape (nz, ny, nx) in C order has x fastest, which is vnr's layout
(no copy); an array of shape (nx, ny, nz) in Fortran order is the same memory (also no copy). Any other
layout (a transposed or strided view) is copied once to C order first. Arrays coming back from vnr
(decode, normalised, to_numpy) are (nz, ny, nx) in C order: index them as a[z, y, x].)";

}  // namespace

Volume volume_from_numpy(const pyb::array& in, std::optional<double> lo, std::optional<double> hi,
                         NonFinitePolicy policy) {
  check_volume_array(in);
  const DType dtype = vnr_dtype(in.dtype());
  pyb::array a = in;
  std::optional<Int3> dims = dims_of_layout(a);
  if (!dims) {  // not x-fastest in memory: one C-order copy
    a = pyb::array::ensure(in, pyb::array::c_style);
    dims = dims_of_layout(a);
  }
  const bool big = big_endian_of(a.dtype());
  const void* samples = a.data();
  pyb::gil_scoped_release release;
  return volume_from_samples(samples, dtype, *dims, big, lo, hi, policy);
}

void bind_volume(pyb::module_& m) {
  pyb::class_<Volume, std::shared_ptr<Volume>> v(m, "Volume", kVolumeDoc);
  v.def_static(
      "from_numpy",
      [](const pyb::array& a, std::optional<std::pair<std::optional<double>, std::optional<double>>> range,
         const std::string& nan) {
        std::optional<double> lo, hi;
        if (range) std::tie(lo, hi) = *range;
        return std::make_shared<Volume>(volume_from_numpy(a, lo, hi, parse_non_finite_policy(nan)));
      },
      pyb::arg("array"), pyb::arg("value_range") = pyb::none(), pyb::arg("nan") = "error",
      R"(A volume from a 3-D numpy array of any numeric dtype (int8, uint8, int16, uint16, int32, uint32,
float32, float64; either byte order), converted exactly as `vnr train` reads a raw file of that dtype
(so training on it gives the CLI's model). Shape (nz, ny, nx) in C order, or (nx, ny, nz) in Fortran
order: x is the fastest axis in memory, and neither is copied; other layouts are copied once.

value_range: (lo, hi) in original units (either may be None): overrides the data's finite min/max.
nan: "error" (NaN/Inf raise ValueError), "zero" or "clamp", as the CLI's --nan.)");
  v.def_static(
      "open",
      [](const std::string& path, std::optional<int> timestep, std::optional<std::tuple<int64_t, int64_t, int64_t>> dims,
         std::optional<std::string> dtype, std::optional<std::string> endian, std::optional<uint64_t> offset,
         std::optional<std::pair<std::optional<double>, std::optional<double>>> range, const std::string& nan) {
        require_file(path, "volume");
        VolumeOpenOptions o;
        o.raw.timestep = timestep;
        if (dims) o.raw.dims = Int3{std::get<0>(*dims), std::get<1>(*dims), std::get<2>(*dims)};
        o.raw.dtype = dtype;
        o.raw.endian = endian;
        o.raw.offset = offset;
        if (range) std::tie(o.raw.range_lo, o.raw.range_hi) = *range;
        o.load.non_finite = parse_non_finite_policy(nan);
        pyb::gil_scoped_release release;
        return std::make_shared<Volume>(open_volume(path, o));
      },
      pyb::arg("path"), pyb::arg("timestep") = pyb::none(), pyb::kw_only(), pyb::arg("dims") = pyb::none(),
      pyb::arg("dtype") = pyb::none(), pyb::arg("endian") = pyb::none(), pyb::arg("offset") = pyb::none(),
      pyb::arg("value_range") = pyb::none(), pyb::arg("nan") = "error",
      R"(Opens any volume source the CLI reads: a JSON sidecar, an instantvnr scene, NRRD/NHDR, or a raw
file (with dims=(x, y, z) and dtype), one timestep of a series with timestep. The keyword arguments are
the CLI's --dims --dtype --endian --offset --range --nan. A missing file raises FileNotFoundError, bad
input ValueError.)");
  v.def_property_readonly("dims", [](const Volume& vol) { return std::make_tuple(vol.dims.x, vol.dims.y, vol.dims.z); },
                          "Voxels per axis (x, y, z), x fastest.");
  v.def_property_readonly("shape", [](const Volume& vol) { return pyb::tuple(pyb::cast(shape_of(vol.dims))); },
                          "The numpy shape (nz, ny, nx) of its arrays.");
  v.def_property_readonly("source_dtype", [](const Volume& vol) { return numpy_dtype(vol.source_dtype); },
                          "The dtype the values came in (what decode(dtype='source') gives back).");
  v.def_property_readonly("value_range", [](const Volume& vol) { return std::make_pair(vol.lo, vol.hi); },
                          "(lo, hi) in original units: 0 and 1 of the normalised values.");
  v.def_property_readonly(
      "normalised",
      [](std::shared_ptr<Volume> vol) { return view_of_floats(vol->data.data(), vol->dims, vol); },
      "The normalised values in [0, 1] as a read-only float32 array (nz, ny, nx), sharing vnr's memory.");
  v.def(
      "to_numpy",
      [](const Volume& vol) {
        pyb::array_t<float> out(shape_of(vol.dims));
        float* dst = out.mutable_data();
        pyb::gil_scoped_release release;
        const double lo = vol.lo, w = vol.hi - vol.lo;
        for (size_t i = 0; i < vol.data.size(); ++i) dst[i] = float(lo + double(vol.data[i]) * w);
        return out;
      },
      "The values in original units (lo + u (hi - lo)) as a new float32 array (nz, ny, nx).");
  v.def("__repr__", [](const Volume& vol) {
    return fmt::format("vnr.Volume({}x{}x{} {}, value_range=({:g}, {:g}))", vol.dims.x, vol.dims.y, vol.dims.z,
                       dtype_name(vol.source_dtype), vol.lo, vol.hi);
  });
}

}  // namespace vnr::py
