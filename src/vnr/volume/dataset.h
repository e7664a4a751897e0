#pragma once
// Internal to the volume layer: volumes stored as an HDF5 dataset ("file.h5:/group/dataset", also
// .hdf5/.he5) or a NetCDF variable ("file.nc:variable", also .nc4; classic and NetCDF-4 files, read
// through libnetcdf). Axes: the dataspace is C order, (nz, ny, nx) as numpy/h5py write it, so x (the
// fastest axis of a vnr volume) is the LAST axis; a 4-D dataset is (nt, nz, ny, nx), NetCDF's usual
// (time, z, y, x), and is a time series. Samples are read as the native C type of the stored dtype
// (no CF scale_factor/add_offset or _FillValue handling), so they normalise exactly like a raw file
// of the same values.
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>
#include "vnr/volume/formats.h"
#include "vnr/volume/volume.h"

namespace vnr::detail {

struct DatasetPath {
  std::string file;      // the container file
  std::string name;      // dataset path (HDF5) or variable name (NetCDF)
  std::string encoding;  // "hdf5" or "netcdf"
};

// "hdf5" for .h5/.hdf5/.he5, "netcdf" for .nc/.nc4 (extension_of's lower-case form), else "".
std::string dataset_encoding_of_extension(const std::string& ext);
inline bool is_dataset_encoding(const std::string& encoding) {
  return encoding == "hdf5" || encoding == "netcdf";
}

// Splits "FILE.h5:/g/d" at the last ':' whose left side ends in a recognised extension; nullopt when
// the path has no such ':' (then it is an ordinary path).
std::optional<DatasetPath> split_dataset_path(const std::string& path);

// The description of a dataset: dims, dtype and timesteps from the dataspace and type; one clear error
// for a missing file/dataset/variable, a group, a non-numeric or unsupported type, a rank other than
// 3 or 4. Nothing is read but metadata.
Source describe_dataset(const DatasetPath& p);

// The error for a plain path to an HDF5/NetCDF file without ":dataset": names the 3-D or 4-D numeric
// datasets/variables it holds.
[[noreturn]] void fail_no_dataset_path(const std::string& path, const std::string& encoding);

// Boxes of one timestep of a described dataset, as native samples of desc.dtype (x fastest).
// Thread-safe: calls are serialised (neither library reads concurrently).
class DatasetReader {
public:
  virtual ~DatasetReader() = default;
  // Voxels [origin, origin + size) (inside the volume) into dst: size.count() samples.
  virtual void read_box(Int3 origin, Int3 size, unsigned char* dst) = 0;
  // z-slices per storage chunk (1 for contiguous data): sequential readers read whole multiples.
  virtual int64_t chunk_slices() const = 0;
};

// Opens desc's file and dataset and checks they still match desc (dims, dtype).
std::unique_ptr<DatasetReader> open_dataset_reader(const VolumeDesc& desc);
std::unique_ptr<DatasetReader> open_hdf5_reader(const VolumeDesc& desc);
std::unique_ptr<DatasetReader> open_netcdf_reader(const VolumeDesc& desc);
Source describe_hdf5(const DatasetPath& p);
Source describe_netcdf(const DatasetPath& p);
[[noreturn]] void fail_no_hdf5_dataset_path(const std::string& path);
[[noreturn]] void fail_no_netcdf_variable(const std::string& path);

// Voxels [first, first + n) in file order (x fastest) into dst, with at most five box reads.
void read_voxel_run(DatasetReader& r, Int3 dims, uint64_t first, uint64_t n, size_t esize, unsigned char* dst);

// "3-D or 4-D numeric {kind}s here: a, b" (at most 20 named), or that there are none: the list the
// errors for a missing or unusable dataset/variable end with.
std::string volume_names_text(const std::vector<std::string>& names, const std::string& kind);

// Fails unless the dataset, opened again, still has desc's dims, dtype and timestep count (`now`).
void check_dataset_unchanged(const VolumeDesc& desc, const VolumeDesc& now, const std::string& where);

// A chunk cache that holds one z-layer of chunks plus one (at least libhdf5's default 1 MiB, at most
// 256 MiB), so that a slab or box read decompresses each chunk it touches once. chunk: the chunk's
// C-order extents ((nt,) nz, ny, nx), rank 3 or 4.
struct ChunkCacheSize {
  uint64_t bytes = 0, chunk_bytes = 0;
};
ChunkCacheSize layer_chunk_cache(const VolumeDesc& desc, const uint64_t* chunk, int rank);

// The dims and timestep count of a C-order extent list of rank 3 or 4 ((nt,) nz, ny, nx); `what`
// names the dataset in the rank error.
void dims_from_extents(const uint64_t* extents, int rank, const std::string& what, VolumeDesc* d);

}  // namespace vnr::detail
