// HDF5 datasets and NetCDF variables as volumes. The files are written by h5py and netCDF4 (Debian's
// python3-h5py / python3-netcdf4, run through /usr/bin/python3); every dataset's array is also written
// with numpy's tofile + a vnr sidecar, and the raw path is the reference: loads, slabs, value ranges,
// random access and CLI training must give the same bits from either.
#include <gtest/gtest.h>
#include <cstdlib>
#include <string>
#include <vector>
#include "test_support.h"
#include "vnr/volume/raw_access.h"
#include "vnr/volume/stream.h"

namespace vnr::test {
namespace {

const char* kDtypes[] = {"int8", "uint8", "int16", "uint16", "int32", "uint32", "float32", "float64"};
const char* kLayouts[] = {"contiguous", "chunked16", "slices", "gzip4", "shuffle_gzip"};

// Writes every test file into argv[1]. Arrays are (nz, ny, nx) = (21, 19, 35): not multiples of
// the 16^3 chunks, so edge chunks are partial.
const char* kWriter = R"PY(
import json, sys
import numpy as np
import h5py
out = sys.argv[1]
shape = (21, 19, 35)
rng = np.random.default_rng(7)

def values(dt, shape=shape):
    dt = np.dtype(dt)
    if dt.kind == 'f':  # far from zero: the loaders' pivot matters
        return (rng.standard_normal(shape) * 1000 + 1e6 + 0.25).astype(dt)
    info = np.iinfo(dt)
    return rng.integers(info.min, info.max, size=shape, endpoint=True).astype(dt)

def sidecar(name, a):
    a.tofile(f'{out}/{name}.raw')
    json.dump({'file': f'{name}.raw', 'dims': [a.shape[2], a.shape[1], a.shape[0]], 'dtype': str(a.dtype),
               'byte_order': 'little'}, open(f'{out}/{name}.json', 'w'))

dtypes = ['int8', 'uint8', 'int16', 'uint16', 'int32', 'uint32', 'float32', 'float64']
arrays = {dt: values(dt) for dt in dtypes}
layouts = {'contiguous': {}, 'chunked16': dict(chunks=(16, 16, 16)), 'slices': dict(chunks=(1,) + shape[1:]),
           'gzip4': dict(chunks=(16, 16, 16), compression='gzip', compression_opts=4),
           'shuffle_gzip': dict(chunks=(4, 8, 16), shuffle=True, compression='gzip', compression_opts=4)}
series = values('float32', (3,) + shape)
with h5py.File(f'{out}/vols.h5', 'w') as f:
    for dt, a in arrays.items():
        sidecar(dt, a)
        for name, kw in layouts.items():
            f.create_dataset(f'{dt}/{name}', data=a, **kw)
    f.create_dataset('series', data=series, chunks=(1, 8, 8, 8), compression='gzip')
    for t in range(3):
        sidecar(f'series_{t}', series[t])
    f.create_dataset('strings', data=np.array([b'ab'] * 8).reshape(2, 2, 2))
    f.create_dataset('flat', data=arrays['uint8'][0])
    f.create_dataset('five', data=np.zeros((2, 2, 2, 2, 2), np.float32))
    f.create_dataset('i64', data=np.zeros((2, 2, 2), np.int64))
    f.create_dataset('lzf', data=arrays['uint8'], chunks=(8, 8, 8), compression='lzf')
    f.create_group('grp/sub')

try:
    import netCDF4
except ImportError:
    sys.exit(0)
for fmt, names in [('NETCDF4', dtypes), ('NETCDF3_CLASSIC', ['int8', 'int16', 'int32', 'float32', 'float64'])]:
    with netCDF4.Dataset(f'{out}/vols_{fmt}.nc', 'w', format=fmt) as d:
        d.createDimension('time', None)
        for n, l in zip('zyx', shape):
            d.createDimension(n, l)
        for dt in names:
            kw = dict(zlib=True, complevel=4, shuffle=True, chunksizes=(8, 8, 16)) if fmt == 'NETCDF4' else {}
            v = d.createVariable(dt, np.dtype(dt), ('z', 'y', 'x'), fill_value=False, **kw)
            v.set_auto_maskandscale(False)
            v[:] = arrays[dt]
        v = d.createVariable('series', 'f4', ('time', 'z', 'y', 'x'), fill_value=False)
        v[0:3] = series
        d.createVariable('flat', 'f4', ('y', 'x'), fill_value=False)[:] = 0
        d.createVariable('text', 'S1', ('z', 'y', 'x'))
        if fmt == 'NETCDF4':
            d.createVariable('i64', 'i8', ('z', 'y', 'x'), fill_value=False)[:] = 0
)PY";

bool python_has(const char* module) {
  return std::system(("/usr/bin/python3 -c 'import " + std::string(module) + "' >/dev/null 2>&1").c_str()) == 0;
}

class DatasetVolumes : public ::testing::Test {
protected:
  static void SetUpTestSuite() {
    have_h5py_ = python_has("h5py");
    have_netcdf4_ = python_has("netCDF4");
    if (!have_h5py_) return;
    dir_ = temp_dir("vnr_hdf5");
    write_bytes(dir_ + "/writer.py", kWriter);
    const int rc = std::system(("/usr/bin/python3 " + dir_ + "/writer.py " + dir_).c_str());
    ASSERT_EQ(rc, 0) << "the h5py/netCDF4 writer failed";
  }
  void SetUp() override {
    if (!have_h5py_) GTEST_SKIP() << "h5py is not installed for /usr/bin/python3 (Debian: python3-h5py)";
  }
  void require_netcdf4() {
    if (!have_netcdf4_) GTEST_SKIP() << "netCDF4 is not installed for /usr/bin/python3 (Debian: python3-netcdf4)";
  }
  static std::string at(const std::string& name) { return dir_ + "/" + name; }

  static inline bool have_h5py_ = false, have_netcdf4_ = false;
  static inline std::string dir_;
};

// load_volume of `path` equals load_volume of the raw reference bit for bit (dims, dtype, range,
// every value); for_each_slab in 4-slice slabs and scan_value_range agree with it.
void expect_same_as_raw(const std::string& path, const std::string& raw_json) {
  SCOPED_TRACE(path);
  const VolumeDesc desc = describe_volume(path), raw = describe_volume(raw_json);
  ASSERT_EQ(desc.dims, raw.dims);
  ASSERT_EQ(desc.dtype, raw.dtype);
  const Volume v = load_volume(desc), r = load_volume(raw);
  EXPECT_EQ(v.lo, r.lo);
  EXPECT_EQ(v.hi, r.hi);
  ASSERT_EQ(v.data.size(), r.data.size());
  int64_t differ = 0;
  for (size_t i = 0; i < v.data.size(); ++i) differ += bits(v.data[i]) != bits(r.data[i]);
  EXPECT_EQ(differ, 0);
  const ValueRange range = scan_value_range(desc);
  EXPECT_EQ(range.lo, r.lo);
  EXPECT_EQ(range.hi, r.hi);
  const int64_t slice = desc.dims.x * desc.dims.y;
  int64_t next_z = 0, slab_differ = 0;
  for_each_slab(desc, r.lo, r.hi, {}, 4 * slice, [&](int64_t z0, int64_t nz, const float* values) {
    EXPECT_EQ(z0, next_z);
    next_z = z0 + nz;
    for (int64_t i = 0; i < nz * slice; ++i) slab_differ += bits(values[i]) != bits(r.data[size_t(z0 * slice + i)]);
  });
  EXPECT_EQ(next_z, desc.dims.z);
  EXPECT_EQ(slab_differ, 0);
}

TEST_F(DatasetVolumes, Hdf5DtypesAndLayoutsEqualTheRawPath) {
  for (const char* dt : kDtypes)
    for (const char* layout : kLayouts)
      expect_same_as_raw(at("vols.h5") + ":/" + dt + "/" + layout, at(std::string(dt) + ".json"));
}

TEST_F(DatasetVolumes, DescriptionMapsTheLastAxisToX) {
  const VolumeDesc d = describe_volume(at("vols.h5:/uint16/gzip4"));
  EXPECT_EQ(d.dims, (Int3{35, 19, 21}));  // h5py shape (21, 19, 35)
  EXPECT_EQ(d.dtype, DType::UInt16);
  EXPECT_EQ(d.encoding, "hdf5");
  EXPECT_EQ(d.dataset, "/uint16/gzip4");
  EXPECT_EQ(d.n_timesteps, 1);
  // The name may leave out the leading '/'.
  EXPECT_EQ(describe_volume(at("vols.h5:uint16/gzip4")).dims, d.dims);
}

TEST_F(DatasetVolumes, NetcdfClassicAndNetcdf4EqualTheRawPath) {
  require_netcdf4();
  for (const char* dt : kDtypes) expect_same_as_raw(at("vols_NETCDF4.nc") + ":" + dt, at(std::string(dt) + ".json"));
  for (const char* dt : {"int8", "int16", "int32", "float32", "float64"})
    expect_same_as_raw(at("vols_NETCDF3_CLASSIC.nc") + ":" + dt, at(std::string(dt) + ".json"));
  EXPECT_EQ(describe_volume(at("vols_NETCDF4.nc:float32")).encoding, "netcdf");
}

TEST_F(DatasetVolumes, FourDimensionalDatasetsAreTimeSeries) {
  std::vector<std::string> sources = {at("vols.h5:/series")};
  if (have_netcdf4_) sources.push_back(at("vols_NETCDF4.nc:series")), sources.push_back(at("vols_NETCDF3_CLASSIC.nc:series"));
  for (const std::string& src : sources) {
    EXPECT_EQ(describe_volume(src).n_timesteps, 3) << src;
    for (int t : {0, 2}) {
      RawOptions o;
      o.timestep = t;
      const VolumeDesc d = describe_volume(src, o);
      EXPECT_EQ(d.timestep, t);
      const Volume v = load_volume(d), r = load_volume(describe_volume(at("series_" + std::to_string(t) + ".json")));
      EXPECT_EQ(v.lo, r.lo) << src << " t=" << t;
      int64_t differ = 0;
      for (size_t i = 0; i < v.data.size(); ++i) differ += bits(v.data[i]) != bits(r.data[i]);
      EXPECT_EQ(differ, 0) << src << " t=" << t;
    }
    RawOptions bad;
    bad.timestep = 3;
    expect_error([&] { describe_volume(src, bad); }, {"timestep 3 out of range", "has 3 timesteps"});
  }
}

// The out-of-core sampler's reader: boxes (with clamp-to-edge ghost layers, at the volume's faces or an inner
// box's) and scattered voxels.
TEST_F(DatasetVolumes, RandomAccessEqualsTheRawFile) {
  for (const std::string src : {at("vols.h5:/float64/shuffle_gzip"), at("vols.h5:/int16/slices")}) {
    SCOPED_TRACE(src);
    const VolumeDesc desc = describe_volume(src);
    const std::string raw_name = desc.dtype == DType::Float64 ? "float64.json" : "int16.json";
    const Volume r = load_volume(describe_volume(at(raw_name)));
    const RawVolumeFile h5(desc, r.lo, r.hi, NonFinitePolicy::Error);
    const RawVolumeFile raw(describe_volume(at(raw_name)), r.lo, r.hi, NonFinitePolicy::Error);
    for (Int3 origin : {Int3{-2, -3, -1}, Int3{5, 7, 3}, Int3{30, 15, 18}, Int3{-1, 0, 19}}) {
      const Int3 size{9, 7, 5};
      std::vector<float> a(size.count()), b(size.count());
      std::vector<unsigned char> scratch(raw.scratch_bytes(size));
      h5.read_box(origin, size, a.data(), nullptr);
      raw.read_box(origin, size, b.data(), scratch.data());
      for (size_t i = 0; i < a.size(); ++i) ASSERT_EQ(bits(a[i]), bits(b[i])) << "box at " << origin.x << "," << i;
      // Clamped at the faces of an inner box (a brick's region) instead of the volume's.
      const Box3 inner{{4, 6, 2}, {desc.dims.x - 3, desc.dims.y - 2, desc.dims.z - 4}};
      h5.read_box(origin, size, a.data(), nullptr, inner);
      raw.read_box(origin, size, b.data(), scratch.data(), inner);
      for (size_t i = 0; i < a.size(); ++i) ASSERT_EQ(bits(a[i]), bits(b[i])) << "clamped box at " << origin.x << "," << i;
    }
    std::vector<int64_t> idx;
    for (int64_t i = 0; i < 500; ++i) idx.push_back((i * 7919 + 13) % int64_t(desc.dims.count()));
    idx.push_back(int64_t(desc.dims.count()) - 1);
    std::vector<float> a(idx.size()), b(idx.size());
    h5.read_voxels(idx.data(), int64_t(idx.size()), a.data());
    raw.read_voxels(idx.data(), int64_t(idx.size()), b.data());
    for (size_t i = 0; i < a.size(); ++i) ASSERT_EQ(bits(a[i]), bits(b[i])) << "voxel " << idx[i];
    for (size_t i = 0; i < a.size(); ++i) ASSERT_EQ(bits(a[i]), bits(r.data[size_t(idx[i])]));
    EXPECT_NO_THROW(h5.check_unchanged());
  }
}

TEST_F(DatasetVolumes, Hdf5ErrorsAreOneClearLine) {
  expect_error([&] { describe_volume(at("missing.h5") + ":/v"); }, {"missing.h5"});
  expect_error([&] { describe_volume(at("vols.h5:/nope")); }, {"has no dataset '/nope'", "/float32/chunked16", "(42 in all)"});
  expect_error([&] { describe_volume(at("vols.h5:/nogroup/v")); }, {"no group '/nogroup'"});
  expect_error([&] { describe_volume(at("vols.h5:/grp")); }, {":/grp' is a group, not a dataset"});
  expect_error([&] { describe_volume(at("vols.h5:/strings")); }, {"/strings' holds strings, not numbers"});
  expect_error([&] { describe_volume(at("vols.h5:/flat")); }, {"/flat' has 2 dimensions", "3 (z, y, x) or 4"});
  expect_error([&] { describe_volume(at("vols.h5:/five")); }, {"/five' has 5 dimensions"});
  expect_error([&] { describe_volume(at("vols.h5:/i64")); }, {"/i64' holds 64-bit integers"});
  expect_error([&] { describe_volume(at("vols.h5")); },
               {"holds no dataset path; give FILE.h5:/DATASET", "3-D or 4-D numeric datasets here: /float32/chunked16"});
  expect_error([&] { describe_volume(at("int8.json") + ":/v"); }, {"int8.json:/v"});  // not a dataset suffix
  expect_error([&] { describe_volume(at("int8.raw.h5:/v")); }, {"int8.raw.h5"});
  write_bytes(at("not_hdf5.h5"), 64);
  expect_error([&] { describe_volume(at("not_hdf5.h5:/v")); }, {"is not an HDF5 file"});
  RawOptions dims;
  dims.dims = Int3{35, 19, 21};
  expect_error([&] { describe_volume(at("vols.h5:/uint8/contiguous"), dims); }, {"--dims does not apply"});
  // A filter libhdf5 lacks (h5py's own LZF): described, then one error at the first read.
  const VolumeDesc lzf = describe_volume(at("vols.h5:/lzf"));
  expect_error([&] { load_volume(lzf); }, {"cannot read", "/lzf", "filter 'lzf' is not registered"});
}

TEST_F(DatasetVolumes, NetcdfErrorsAreOneClearLine) {
  require_netcdf4();
  const std::string nc = at("vols_NETCDF4.nc");
  expect_error([&] { describe_volume(nc + ":nope"); }, {"has no variable 'nope'", "numeric variables here:", "float32"});
  expect_error([&] { describe_volume(nc + ":flat"); }, {"has 2 dimensions"});
  expect_error([&] { describe_volume(nc + ":text"); }, {"holds text, not numbers"});
  expect_error([&] { describe_volume(nc + ":i64"); }, {"holds 64-bit integers"});
  expect_error([&] { describe_volume(nc); }, {"holds no variable name; give FILE.nc:VARIABLE", "series"});
  expect_error([&] { describe_volume(at("missing.nc:v")); }, {"missing.nc"});
}

// The command line on an HDF5 dataset: training, evaluation and the out-of-core sampler give what
// they give on the raw file of the same values (same seed: same loss curve, same PSNR line).
TEST_F(DatasetVolumes, CliTrainsAndEvaluatesOnHdf5LikeOnRaw) {
  const std::string common = " --config small --batch 1024 --steps 20 --threads 2 --seed 5 -q";
  for (const std::string& sampler : {std::string(""), std::string(" --sampler outofcore --block-dims 8,8,8 "
                                                                    "--memory-budget 64KiB")}) {
    SCOPED_TRACE(sampler);
    Result a = run("train " + at("vols.h5:/uint16/gzip4") + " -o " + at("h5.vnr") + common + sampler + " --report " +
                   at("h5.json"));
    ASSERT_EQ(a.code, 0) << a.err;
    Result b = run("train " + at("uint16.json") + " -o " + at("raw.vnr") + common + sampler + " --report " +
                   at("raw.json"));
    ASSERT_EQ(b.code, 0) << b.err;
    const Json ja = parse_json_file(at("h5.json")), jb = parse_json_file(at("raw.json"));
    EXPECT_EQ(ja["sampler"], jb["sampler"]);
    EXPECT_EQ(ja["loss_history"], jb["loss_history"]);
    EXPECT_EQ(ja["final_loss"], jb["final_loss"]);
    EXPECT_EQ(ja["psnr"], jb["psnr"]);
  }
  // Whole-volume (streamed in slabs under a small budget, and in memory) and sampled evaluation.
  for (const std::string opts : {" --threads 2 -q", " --threads 2 -q --memory-budget 16KiB",
                                 " --threads 2 -q --sample 2000"}) {
    Result e1 = run("eval " + at("h5.vnr") + " " + at("vols.h5:/uint16/gzip4") + opts);
    Result e2 = run("eval " + at("h5.vnr") + " " + at("uint16.json") + opts);
    ASSERT_EQ(e1.code, 0) << opts << "\n" << e1.err;
    ASSERT_EQ(e2.code, 0) << opts << "\n" << e2.err;
    EXPECT_HAS(e1.out, "PSNR");
    EXPECT_EQ(e1.out.substr(0, e1.out.find("decoded in")), e2.out.substr(0, e2.out.find("decoded in"))) << opts;
  }
  Result info = run("info " + at("h5.vnr"));
  ASSERT_EQ(info.code, 0) << info.err;
  EXPECT_HAS(info.out, "35x19x21 uint16");
  // Rendering the ground truth, and a model with the dataset as --volume (macro-cells from it).
  for (const std::string& src : {std::string("vols.h5:/uint16/gzip4"), std::string("uint16.json")}) {
    const std::string tag = src == "uint16.json" ? "raw" : "h5";
    Result r1 = run("render " + at(src) + " -o " + at(tag + "_gt.png") + " --size 48x40 --threads 2");
    ASSERT_EQ(r1.code, 0) << r1.err;
    Result r2 = run("render " + at("h5.vnr") + " --volume " + at(src) + " --macrocells grid -o " + at(tag + "_nn.png") +
                    " --size 48x40 --threads 2");
    ASSERT_EQ(r2.code, 0) << r2.err;
  }
  EXPECT_EQ(read_file(at("h5_gt.png")), read_file(at("raw_gt.png")));
  EXPECT_EQ(read_file(at("h5_nn.png")), read_file(at("raw_nn.png")));
  Result described = run("info " + at("vols.h5:/series"));
  ASSERT_EQ(described.code, 0) << described.err;
  EXPECT_HAS(described.out, "HDF5 dataset /series, 35x19x21 float32 (x = the last axis), 3 timesteps");
  expect_error("info " + at("vols.h5"), "give FILE.h5:/DATASET");
  expect_error("train " + at("vols.h5:/uint16/gzip4") + " -o " + at("m.vnr") + " --steps 2 --sampler mmap",
               "use --sampler outofcore");
  expect_error("train " + at("vols.h5") + " -o " + at("m.vnr") + " --steps 2", "give FILE.h5:/DATASET");
}

}  // namespace
}  // namespace vnr::test
