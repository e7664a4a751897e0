// HDF5 datasets as volumes (libhdf5's C API): description from the dataspace and type, reads as
// hyperslab selections, with a chunk cache that holds a whole z-layer of chunks so that streaming
// slabs and out-of-core boxes decompress each chunk once.
#include <algorithm>
#include <mutex>
#include <vector>
#include "vnr/error.h"
#include "vnr/volume/dataset.h"

#if VNR_HAVE_HDF5
#include <hdf5.h>

namespace vnr::detail {
namespace {

// An HDF5 identifier closed by its own close function when this goes out of scope.
class Hid {
public:
  Hid() = default;
  Hid(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
  Hid(Hid&& o) noexcept : id_(o.id_), close_(o.close_) { o.id_ = -1; }
  Hid& operator=(Hid&& o) noexcept {
    std::swap(id_, o.id_);
    std::swap(close_, o.close_);
    return *this;
  }
  ~Hid() {
    if (id_ >= 0 && close_) close_(id_);
  }
  hid_t get() const { return id_; }
  bool ok() const { return id_ >= 0; }

private:
  hid_t id_ = -1;
  herr_t (*close_)(hid_t) = nullptr;
};

// HDF5 prints its error stack on stderr by default; vnr says one line of its own instead. The
// setting is per thread, so every entry point sets it.
void quiet() { H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr); }

// The telling line of the current error stack: the first that names a filter (a missing one reads
// "required filter 'lzf' is not registered"; below it are only the plugin search's failures), else
// the innermost.
std::string hdf5_error_text() {
  std::vector<std::string> lines;
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_DOWNWARD,
           [](unsigned, const H5E_error2_t* e, void* out) -> herr_t {
             if (e->desc && *e->desc) static_cast<std::vector<std::string>*>(out)->push_back(e->desc);
             return 0;
           },
           &lines);
  for (const std::string& l : lines)
    if (l.find("filter") != std::string::npos) return l;
  return lines.empty() ? "unknown HDF5 error" : lines.back();
}

const char* class_text(H5T_class_t c) {
  switch (c) {
    case H5T_STRING: return "strings";
    case H5T_COMPOUND: return "compound records";
    case H5T_ENUM: return "enum values";
    case H5T_BITFIELD: return "bit fields";
    case H5T_OPAQUE: return "opaque data";
    case H5T_REFERENCE: return "references";
    case H5T_VLEN: return "variable-length sequences";
    case H5T_ARRAY: return "arrays";
    default: return "a non-numeric type";
  }
}

DType dtype_of(hid_t type, const std::string& what) {
  const H5T_class_t c = H5Tget_class(type);
  const size_t size = H5Tget_size(type);
  if (c == H5T_INTEGER) {
    const bool is_signed = H5Tget_sign(type) == H5T_SGN_2;
    if (size == 1) return is_signed ? DType::Int8 : DType::UInt8;
    if (size == 2) return is_signed ? DType::Int16 : DType::UInt16;
    if (size == 4) return is_signed ? DType::Int32 : DType::UInt32;
    fail("{} holds {}-bit {}integers; vnr reads int8..int32, uint8..uint32, float32 and float64 (convert it first)",
         what, size * 8, is_signed ? "" : "unsigned ");
  }
  if (c == H5T_FLOAT) {
    if (size == 4) return DType::Float32;
    if (size == 8) return DType::Float64;
    fail("{} holds {}-bit floats; vnr reads float32 and float64 (and int8..uint32)", what, size * 8);
  }
  fail("{} holds {}, not numbers", what, class_text(c));
}

hid_t native_type(DType t) {
  switch (t) {
    case DType::Int8: return H5T_NATIVE_INT8;
    case DType::UInt8: return H5T_NATIVE_UINT8;
    case DType::Int16: return H5T_NATIVE_INT16;
    case DType::UInt16: return H5T_NATIVE_UINT16;
    case DType::Int32: return H5T_NATIVE_INT32;
    case DType::UInt32: return H5T_NATIVE_UINT32;
    case DType::Float32: return H5T_NATIVE_FLOAT;
    case DType::Float64: return H5T_NATIVE_DOUBLE;
  }
  return H5T_NATIVE_FLOAT;
}

Hid open_file(const std::string& path) {
  quiet();
  if (H5Fis_hdf5(path.c_str()) <= 0) fail("'{}' is not an HDF5 file", path);
  Hid f(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (!f.ok()) fail("cannot open HDF5 file '{}': {}", path, hdf5_error_text());
  return f;
}

// Whether the object at `name` is a dataset a volume can come from (3-D or 4-D, of a type vnr reads).
bool is_volume_dataset(hid_t loc, const char* name) {
  Hid obj(H5Oopen(loc, name, H5P_DEFAULT), H5Oclose);
  if (!obj.ok() || H5Iget_type(obj.get()) != H5I_DATASET) return false;
  Hid space(H5Dget_space(obj.get()), H5Sclose), type(H5Dget_type(obj.get()), H5Tclose);
  const int rank = H5Sget_simple_extent_ndims(space.get());
  const H5T_class_t c = H5Tget_class(type.get());
  const size_t size = H5Tget_size(type.get());
  const bool readable = (c == H5T_INTEGER && size <= 4) || (c == H5T_FLOAT && (size == 4 || size == 8));
  return (rank == 3 || rank == 4) && readable;
}

// "3-D or 4-D numeric datasets here: /a, /g/b" (at most 20 named), or that there are none.
std::string volume_datasets_text(hid_t file) {
  std::vector<std::string> names;
  H5Lvisit(file, H5_INDEX_NAME, H5_ITER_INC,
           [](hid_t group, const char* name, const H5L_info_t* info, void* out) -> herr_t {
             if (info->type == H5L_TYPE_HARD && is_volume_dataset(group, name))
               static_cast<std::vector<std::string>*>(out)->push_back(fmt::format("/{}", name));
             return 0;
           },
           &names);
  return volume_names_text(names, "dataset");
}

// The dataset at `name`, with one message for each way it can be missing: a missing group on the
// way, a missing last link, a group or named type instead of a dataset.
Hid open_dataset(hid_t file, const std::string& path, const std::string& name, hid_t dapl) {
  const std::string where = "'" + path + ":" + name + "'";
  for (size_t p = name.find('/', 1); ; p = name.find('/', p + 1)) {
    const std::string prefix = name.substr(0, p);
    if (!prefix.empty() && prefix != "/" && H5Lexists(file, prefix.c_str(), H5P_DEFAULT) <= 0)
      fail("'{}' has no dataset '{}' ({}; {})", path, name,
           p == std::string::npos ? "no such name" : "no group '" + prefix + "'", volume_datasets_text(file));
    if (p == std::string::npos) break;
  }
  Hid obj(H5Oopen(file, name.c_str(), H5P_DEFAULT), H5Oclose);
  if (!obj.ok()) fail("cannot open {}: {}", where, hdf5_error_text());
  const H5I_type_t type = H5Iget_type(obj.get());
  if (type == H5I_GROUP) fail("{} is a group, not a dataset ({})", where, volume_datasets_text(file));
  if (type != H5I_DATASET) fail("{} is not a dataset ({})", where, volume_datasets_text(file));
  Hid d(H5Dopen2(file, name.c_str(), dapl), H5Dclose);
  if (!d.ok()) fail("cannot open {}: {}", where, hdf5_error_text());
  return d;
}

std::vector<hsize_t> extents_of(hid_t dset) {
  Hid space(H5Dget_space(dset), H5Sclose);
  const int rank = H5Sget_simple_extent_ndims(space.get());
  std::vector<hsize_t> e(size_t(std::max(rank, 0)));
  if (rank > 0) H5Sget_simple_extent_dims(space.get(), e.data(), nullptr);
  return e;
}

// Fills d's dims, timesteps and dtype from the dataset.
void describe_open_dataset(hid_t dset, const std::string& where, VolumeDesc* d) {
  const std::vector<hsize_t> e = extents_of(dset);
  std::vector<uint64_t> e64(e.begin(), e.end());
  Hid type(H5Dget_type(dset), H5Tclose);
  d->dtype = dtype_of(type.get(), where);  // first: "holds strings" says more than a rank
  dims_from_extents(e64.data(), int(e64.size()), where, d);
}

class Hdf5Reader final : public DatasetReader {
public:
  explicit Hdf5Reader(const VolumeDesc& desc) : desc_(desc), file_(open_file(desc.path)) {
    const std::string where = "'" + desc.path + ":" + desc.dataset + "'";
    Hid probe = open_dataset(file_.get(), desc.path, desc.dataset, H5P_DEFAULT);
    VolumeDesc now;
    describe_open_dataset(probe.get(), where, &now);
    check_dataset_unchanged(desc, now, where);
    rank_ = int(extents_of(probe.get()).size());  // 3 or 4: describe_open_dataset checked
    Hid dapl(H5Pcreate(H5P_DATASET_ACCESS), H5Pclose);
    set_chunk_cache(probe.get(), dapl.get());
    dset_ = open_dataset(file_.get(), desc.path, desc.dataset, dapl.get());
  }

  void read_box(Int3 origin, Int3 size, unsigned char* dst) override {
    std::lock_guard<std::mutex> lock(mutex_);
    quiet();
    hsize_t start[4], count[4];
    const int k = rank_ - 3;
    if (k) start[0] = hsize_t(desc_.timestep), count[0] = 1;
    start[k] = hsize_t(origin.z), start[k + 1] = hsize_t(origin.y), start[k + 2] = hsize_t(origin.x);
    count[k] = hsize_t(size.z), count[k + 1] = hsize_t(size.y), count[k + 2] = hsize_t(size.x);
    Hid fspace(H5Dget_space(dset_.get()), H5Sclose);
    const hsize_t n = size.count();
    Hid mspace(H5Screate_simple(1, &n, nullptr), H5Sclose);
    if (H5Sselect_hyperslab(fspace.get(), H5S_SELECT_SET, start, nullptr, count, nullptr) < 0 ||
        H5Dread(dset_.get(), native_type(desc_.dtype), mspace.get(), fspace.get(), H5P_DEFAULT, dst) < 0)
      fail("cannot read '{}:{}' (slices {}..{}): {}", desc_.path, desc_.dataset, origin.z, origin.z + size.z - 1,
           hdf5_error_text());
  }

  int64_t chunk_slices() const override { return chunk_slices_; }

private:
  // A chunk cache that holds one z-layer of chunks (dataset.h's layer_chunk_cache).
  void set_chunk_cache(hid_t dset, hid_t dapl) {
    Hid dcpl(H5Dget_create_plist(dset), H5Pclose);
    if (H5Pget_layout(dcpl.get()) != H5D_CHUNKED) return;
    hsize_t c[4] = {1, 1, 1, 1};
    H5Pget_chunk(dcpl.get(), rank_, c);
    chunk_slices_ = int64_t(c[rank_ - 3]);
    const uint64_t c64[4] = {c[0], c[1], c[2], c[3]};
    const ChunkCacheSize cache = layer_chunk_cache(desc_, c64, rank_);
    const uint64_t slots = std::clamp<uint64_t>(100 * (cache.bytes / cache.chunk_bytes + 1) + 1, 521, 1 << 20);
    H5Pset_chunk_cache(dapl, size_t(slots), size_t(cache.bytes), 1.0);
  }

  VolumeDesc desc_;
  Hid file_, dset_;
  int rank_ = 3;
  int64_t chunk_slices_ = 1;
  std::mutex mutex_;
};

}  // namespace

Source describe_hdf5(const DatasetPath& p) {
  Hid file = open_file(p.file);
  const std::string name = p.name[0] == '/' ? p.name : fmt::format("/{}", p.name);
  Hid dset = open_dataset(file.get(), p.file, name, H5P_DEFAULT);
  Source s;
  describe_open_dataset(dset.get(), "'" + p.file + ":" + p.name + "'", &s.desc);
  return s;
}

void fail_no_hdf5_dataset_path(const std::string& path) {
  Hid file = open_file(path);
  fail("'{}' holds no dataset path; give FILE.h5:/DATASET ({})", path, volume_datasets_text(file.get()));
}

std::unique_ptr<DatasetReader> open_hdf5_reader(const VolumeDesc& desc) {
  return std::make_unique<Hdf5Reader>(desc);
}

}  // namespace vnr::detail

#else  // without libhdf5: the suffix is recognised, and says what is missing

namespace vnr::detail {

[[noreturn]] static void no_hdf5(const std::string& path) {
  fail("'{}': vnr was built without HDF5 support (install libhdf5-dev and reconfigure with -DVNR_HDF5=ON)", path);
}
Source describe_hdf5(const DatasetPath& p) { no_hdf5(p.file); }
void fail_no_hdf5_dataset_path(const std::string& path) { no_hdf5(path); }
std::unique_ptr<DatasetReader> open_hdf5_reader(const VolumeDesc& desc) { no_hdf5(desc.path); }

}  // namespace vnr::detail

#endif
