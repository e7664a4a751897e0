// What HDF5 and NetCDF volumes share: path syntax, the axis mapping, and reading runs of voxels as
// boxes. The libraries themselves are behind hdf5_source.cpp and netcdf_source.cpp.
#include "vnr/volume/dataset.h"
#include <algorithm>
#include <bit>
#include "vnr/error.h"
#include "vnr/fileio.h"

namespace vnr::detail {

std::string dataset_encoding_of_extension(const std::string& ext) {
  if (ext == ".h5" || ext == ".hdf5" || ext == ".he5") return "hdf5";
  if (ext == ".nc" || ext == ".nc4") return "netcdf";
  return "";
}

std::optional<DatasetPath> split_dataset_path(const std::string& path) {
  for (size_t p = path.rfind(':'); p != std::string::npos && p > 0; p = path.rfind(':', p - 1)) {
    const std::string file = path.substr(0, p);
    const std::string enc = dataset_encoding_of_extension(extension_of(file));
    if (!enc.empty()) return DatasetPath{file, path.substr(p + 1), enc};
  }
  return std::nullopt;
}

Source describe_dataset(const DatasetPath& p) {
  file_size(p.file);  // missing, unreadable or a directory: says so with the path
  if (p.name.empty() || p.name == "/")
    fail("'{}:{}': empty {} name after ':'", p.file, p.name, p.encoding == "hdf5" ? "dataset" : "variable");
  Source s = p.encoding == "hdf5" ? describe_hdf5(p) : describe_netcdf(p);
  VolumeDesc& d = s.desc;
  d.path = p.file;
  d.dataset = p.name;
  d.encoding = p.encoding;
  d.big_endian = std::endian::native == std::endian::big;  // read as native samples: never swapped
  d.offset = 0;
  s.origin = p.file + ":" + p.name;
  return s;
}

void fail_no_dataset_path(const std::string& path, const std::string& encoding) {
  file_size(path);
  if (encoding == "hdf5") fail_no_hdf5_dataset_path(path);
  fail_no_netcdf_variable(path);
}

std::unique_ptr<DatasetReader> open_dataset_reader(const VolumeDesc& desc) {
  if (desc.encoding == "hdf5") return open_hdf5_reader(desc);
  if (desc.encoding == "netcdf") return open_netcdf_reader(desc);
  fail("'{}': encoding '{}' is not an HDF5 or NetCDF dataset", desc.path, desc.encoding);
}

void dims_from_extents(const uint64_t* extents, int rank, const std::string& what, VolumeDesc* d) {
  if (rank != 3 && rank != 4)
    fail("{} has {} dimension{}; a volume needs 3 (z, y, x) or 4 (time, z, y, x)", what, rank, rank == 1 ? "" : "s");
  const uint64_t* e = extents + (rank - 3);
  for (int a = 0; a < rank; ++a)
    if (extents[a] == 0 || extents[a] > (uint64_t(1) << 30))
      fail("{} has an empty or too large extent ({} along axis {})", what, extents[a], a);
  d->dims = Int3{int64_t(e[2]), int64_t(e[1]), int64_t(e[0])};  // C order: the last axis is x
  d->n_timesteps = rank == 4 ? int(extents[0]) : 1;
}

std::string volume_names_text(const std::vector<std::string>& names, const std::string& kind) {
  if (names.empty()) return "it holds no 3-D or 4-D numeric " + kind;
  std::string text = "3-D or 4-D numeric " + kind + "s here: ";
  for (size_t i = 0; i < names.size() && i < 20; ++i) text += (i ? ", " : "") + names[i];
  if (names.size() > 20) text += fmt::format(", ... ({} in all)", names.size());
  return text;
}

void check_dataset_unchanged(const VolumeDesc& desc, const VolumeDesc& now, const std::string& where) {
  if (now.dims != desc.dims || now.dtype != desc.dtype || now.n_timesteps != desc.n_timesteps)
    fail("{} changed since it was described (now {} {})", where, dims_string(now.dims, now.n_timesteps),
         dtype_name(now.dtype));
}

ChunkCacheSize layer_chunk_cache(const VolumeDesc& desc, const uint64_t* chunk, int rank) {
  const uint64_t cy = std::max<uint64_t>(chunk[rank - 2], 1), cx = std::max<uint64_t>(chunk[rank - 1], 1);
  const uint64_t per_layer = ((uint64_t(desc.dims.x) + cx - 1) / cx) * ((uint64_t(desc.dims.y) + cy - 1) / cy);
  ChunkCacheSize c;
  c.chunk_bytes = dtype_size(desc.dtype);
  for (int a = 0; a < rank; ++a) c.chunk_bytes *= std::max<uint64_t>(chunk[a], 1);
  c.bytes = std::clamp<uint64_t>(per_layer * c.chunk_bytes + c.chunk_bytes, 1 << 20, uint64_t(256) << 20);
  return c;
}

void read_voxel_run(DatasetReader& r, Int3 dims, uint64_t first, uint64_t n, size_t esize, unsigned char* dst) {
  const uint64_t nx = uint64_t(dims.x), slice = nx * uint64_t(dims.y);
  while (n > 0) {
    const uint64_t x = first % nx, y = (first / nx) % uint64_t(dims.y), z = first / slice;
    Int3 origin{int64_t(x), int64_t(y), int64_t(z)}, size{1, 1, 1};
    if (x != 0 || n < nx) {  // the rest of one row
      size.x = int64_t(std::min(nx - x, n));
    } else if (y != 0 || n < slice) {  // whole rows to the end of the slice
      size.x = int64_t(nx);
      size.y = int64_t(std::min(uint64_t(dims.y) - y, n / nx));
    } else {  // whole slices
      size = Int3{dims.x, dims.y, int64_t(n / slice)};
    }
    r.read_box(origin, size, dst);
    const uint64_t m = size.count();
    first += m;
    n -= m;
    dst += m * esize;
  }
}

}  // namespace vnr::detail
