// NetCDF variables as volumes (libnetcdf, so classic, 64-bit offset and NetCDF-4 files all work):
// description from the variable's dimensions and type, reads with nc_get_vara. libnetcdf is not
// thread-safe: every call holds one process-wide lock.
#include <algorithm>
#include <memory>
#include <mutex>
#include <tuple>
#include <vector>
#include "vnr/error.h"
#include "vnr/volume/dataset.h"

#if VNR_HAVE_NETCDF
#include <netcdf.h>

namespace vnr::detail {
namespace {

std::mutex& netcdf_lock() {
  static std::mutex m;
  return m;
}

// An open NetCDF file, closed when this goes out of scope.
class NcFile {
public:
  explicit NcFile(const std::string& path) : path_(path) {
    const int rc = nc_open(path.c_str(), NC_NOWRITE, &id_);
    if (rc != NC_NOERR) fail("cannot open NetCDF file '{}': {}", path, nc_strerror(rc));
  }
  ~NcFile() { nc_close(id_); }
  NcFile(const NcFile&) = delete;
  NcFile& operator=(const NcFile&) = delete;
  int id() const { return id_; }

private:
  std::string path_;
  int id_ = -1;
};

DType dtype_of(nc_type t, const std::string& what) {
  switch (t) {
    case NC_BYTE: return DType::Int8;
    case NC_UBYTE: return DType::UInt8;
    case NC_SHORT: return DType::Int16;
    case NC_USHORT: return DType::UInt16;
    case NC_INT: return DType::Int32;
    case NC_UINT: return DType::UInt32;
    case NC_FLOAT: return DType::Float32;
    case NC_DOUBLE: return DType::Float64;
    case NC_INT64:
    case NC_UINT64:
      fail("{} holds 64-bit integers; vnr reads int8..int32, uint8..uint32, float32 and float64 (convert it first)",
           what);
    case NC_CHAR:
    case NC_STRING: fail("{} holds text, not numbers", what);
    default: fail("{} holds a user-defined type, not numbers", what);
  }
}

// The (group, variable) ids of "var" or "group/sub/var" (NetCDF-4 groups).
std::pair<int, int> find_variable(const NcFile& f, const std::string& path, const std::string& name, bool* found) {
  int group = f.id(), var = -1;
  std::string var_name = name[0] == '/' ? name.substr(1) : name;
  const size_t slash = var_name.rfind('/');
  if (slash != std::string::npos) {
    const std::string group_path = fmt::format("/{}", var_name.substr(0, slash));
    if (nc_inq_grp_full_ncid(f.id(), group_path.c_str(), &group) != NC_NOERR) {
      *found = false;
      return {f.id(), -1};
    }
    var_name = var_name.substr(slash + 1);
  }
  *found = nc_inq_varid(group, var_name.c_str(), &var) == NC_NOERR;
  return {group, var};
}

// "3-D or 4-D numeric variables here: a, b" for the root group (at most 20 named), or that there are none.
std::string volume_variables_text(int ncid) {
  int n = 0;
  nc_inq_nvars(ncid, &n);
  std::vector<std::string> names;
  for (int v = 0; v < n; ++v) {
    char name[NC_MAX_NAME + 1] = {};
    nc_type t;
    int rank = 0;
    if (nc_inq_var(ncid, v, name, &t, &rank, nullptr, nullptr) != NC_NOERR) continue;
    const bool numeric = t == NC_BYTE || t == NC_UBYTE || t == NC_SHORT || t == NC_USHORT || t == NC_INT ||
                         t == NC_UINT || t == NC_FLOAT || t == NC_DOUBLE;
    if (numeric && (rank == 3 || rank == 4)) names.push_back(name);
  }
  return volume_names_text(names, "variable");
}

struct Variable {
  int group = -1, var = -1, rank = 0;
  std::vector<size_t> extents;
  nc_type type = NC_NAT;
};

Variable open_variable(const NcFile& f, const std::string& path, const std::string& name) {
  bool found = false;
  Variable v;
  std::tie(v.group, v.var) = find_variable(f, path, name, &found);
  if (!found) fail("'{}' has no variable '{}' ({})", path, name, volume_variables_text(f.id()));
  int dimids[NC_MAX_VAR_DIMS];
  nc_inq_var(v.group, v.var, nullptr, &v.type, &v.rank, dimids, nullptr);
  for (int a = 0; a < v.rank; ++a) {
    size_t len = 0;
    nc_inq_dimlen(v.group, dimids[a], &len);
    v.extents.push_back(len);
  }
  return v;
}

void describe_variable(const Variable& v, const std::string& where, VolumeDesc* d) {
  std::vector<uint64_t> e(v.extents.begin(), v.extents.end());
  d->dtype = dtype_of(v.type, where);  // first: "holds text" says more than a rank
  dims_from_extents(e.data(), v.rank, where, d);
}

class NetcdfReader final : public DatasetReader {
public:
  explicit NetcdfReader(const VolumeDesc& desc) : desc_(desc) {
    std::lock_guard<std::mutex> lock(netcdf_lock());
    file_ = std::make_unique<NcFile>(desc.path);
    try {  // the file closes under the lock: the destructor does not run when this throws
      v_ = open_variable(*file_, desc.path, desc.dataset);
      VolumeDesc now;
      const std::string where = "'" + desc.path + ":" + desc.dataset + "'";
      describe_variable(v_, where, &now);
      check_dataset_unchanged(desc, now, where);
      set_chunk_cache();
    } catch (...) {
      file_.reset();
      throw;
    }
  }
  ~NetcdfReader() override {
    std::lock_guard<std::mutex> lock(netcdf_lock());
    file_.reset();
  }

  void read_box(Int3 origin, Int3 size, unsigned char* dst) override {
    size_t start[4], count[4];
    const int k = v_.rank - 3;
    if (k) start[0] = size_t(desc_.timestep), count[0] = 1;
    start[k] = size_t(origin.z), start[k + 1] = size_t(origin.y), start[k + 2] = size_t(origin.x);
    count[k] = size_t(size.z), count[k + 1] = size_t(size.y), count[k + 2] = size_t(size.x);
    std::lock_guard<std::mutex> lock(netcdf_lock());
    const int rc = nc_get_vara(v_.group, v_.var, start, count, dst);
    if (rc != NC_NOERR)
      fail("cannot read '{}:{}' (slices {}..{}): {}", desc_.path, desc_.dataset, origin.z, origin.z + size.z - 1,
           nc_strerror(rc));
  }

  int64_t chunk_slices() const override { return chunk_slices_; }

private:
  // NetCDF-4 chunked variables: a cache that holds one z-layer of chunks (as for HDF5).
  void set_chunk_cache() {
    int storage = NC_CONTIGUOUS;
    size_t c[NC_MAX_VAR_DIMS] = {};
    if (nc_inq_var_chunking(v_.group, v_.var, &storage, c) != NC_NOERR || storage != NC_CHUNKED) return;
    chunk_slices_ = int64_t(std::max<size_t>(c[v_.rank - 3], 1));
    uint64_t c64[4] = {};  // rank 3 or 4 (describe_variable checked)
    std::copy(c, c + v_.rank, c64);
    const ChunkCacheSize cache = layer_chunk_cache(desc_, c64, v_.rank);
    nc_set_var_chunk_cache(v_.group, v_.var, size_t(cache.bytes),
                           size_t(std::max<uint64_t>(521, 4 * (cache.bytes / cache.chunk_bytes + 1))), 1.0f);
  }

  VolumeDesc desc_;
  std::unique_ptr<NcFile> file_;
  Variable v_;
  int64_t chunk_slices_ = 1;
};

}  // namespace

Source describe_netcdf(const DatasetPath& p) {
  std::lock_guard<std::mutex> lock(netcdf_lock());
  NcFile f(p.file);
  Source s;
  describe_variable(open_variable(f, p.file, p.name), "'" + p.file + ":" + p.name + "'", &s.desc);
  return s;
}

void fail_no_netcdf_variable(const std::string& path) {
  std::lock_guard<std::mutex> lock(netcdf_lock());
  NcFile f(path);
  fail("'{}' holds no variable name; give FILE.nc:VARIABLE ({})", path, volume_variables_text(f.id()));
}

std::unique_ptr<DatasetReader> open_netcdf_reader(const VolumeDesc& desc) {
  return std::make_unique<NetcdfReader>(desc);
}

}  // namespace vnr::detail

#else  // without libnetcdf: the suffix is recognised, and says what is missing

namespace vnr::detail {

[[noreturn]] static void no_netcdf(const std::string& path) {
  fail("'{}': vnr was built without NetCDF support (install libnetcdf-dev and reconfigure with -DVNR_NETCDF=ON)",
       path);
}
Source describe_netcdf(const DatasetPath& p) { no_netcdf(p.file); }
void fail_no_netcdf_variable(const std::string& path) { no_netcdf(path); }
std::unique_ptr<DatasetReader> open_netcdf_reader(const VolumeDesc& desc) { no_netcdf(desc.path); }

}  // namespace vnr::detail

#endif
