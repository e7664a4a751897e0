// Out-of-core and memory-mapped training samplers (paper, "Out-of-Core Sampling"): block
// interpolation, box reads and mapped lookups equal load_volume and the in-memory lookup bit for
// bit, reads stay inside the file, the buffer stays inside the memory budget, training converges
// like in-core sampling, and a volume file that changes under a run gives a clear error (and,
// from the CLI, keeps the model trained so far).
#include <gtest/gtest.h>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <random>
#include <thread>
#include <fmt/format.h>
#include "vnr/fileio.h"
#include "vnr/core/parallel.h"
#include "vnr/model_config.h"
#include "vnr/train/model_io.h"
#include "vnr/train/streaming_samplers.h"
#include "vnr/train/trainer.h"
#include "vnr/volume/stream.h"
#include "vnr/volume_writer.h"
#include "test_support.h"

using namespace vnr;
using namespace vnr::test;
namespace fs = std::filesystem;

namespace {

// A uint16 volume with random values behind a `header`-byte header, `timesteps` frames one after
// another, described by a sidecar (integers normalise exactly on every path, so equality is exact).
std::string write_u16_volume(const std::string& name, Int3 d, uint64_t header = 0, int timesteps = 1,
                             uint32_t seed = 5) {
  std::string raw = temp_dir("vnr_ooc") + "/" + name + ".raw", json = temp_dir("vnr_ooc") + "/" + name + ".json";
  std::ofstream f(raw, std::ios::binary);
  std::mt19937 rng(seed);
  std::vector<unsigned char> pad(header, 0xEE);
  f.write(reinterpret_cast<const char*>(pad.data()), std::streamsize(header));
  std::vector<uint16_t> v(d.count() * uint64_t(timesteps));
  for (auto& x : v) x = uint16_t(rng() % 60000);
  f.write(reinterpret_cast<const char*>(v.data()), std::streamsize(v.size() * 2));
  f.close();
  write_file_atomic(json, fmt::format(R"({{"file": "{}.raw", "dims": [{}, {}, {}, {}], "dtype": "uint16", "offset": {}}})",
                                      name, d.x, d.y, d.z, timesteps, header));
  return json;
}

struct Samples {
  std::vector<float> x, y, z, t;
};
// read_box's result for the box [origin, origin + size) must be load_volume's voxels, clamped to the
// edge outside the volume (or outside clamp_to), bit for bit.
void expect_box_is_clamped_copy(const Volume& vol, Int3 origin, Int3 size, const std::vector<float>& box,
                                std::optional<Box3> clamp_to = std::nullopt) {
  const Int3 d = vol.dims;
  const Box3 c = clamp_to ? *clamp_to : Box3{{0, 0, 0}, d};
  auto clamp = [&](int64_t v, int a) { return std::clamp<int64_t>(v, c.lo[a], c.hi[a] - 1); };
  for (int64_t z = 0; z < size.z; ++z)
    for (int64_t y = 0; y < size.y; ++y)
      for (int64_t x = 0; x < size.x; ++x) {
        const float want = vol.data[size_t(
            (clamp(origin.z + z, 2) * d.y + clamp(origin.y + y, 1)) * d.x + clamp(origin.x + x, 0))];
        const float got = box[size_t((z * size.y + y) * size.x + x)];
        ASSERT_EQ(std::memcmp(&got, &want, sizeof(float)), 0) << "box voxel " << x << "," << y << "," << z;
      }
}

Samples draw(const Sampler& s, uint64_t seed, uint64_t step, int n) {
  Samples o{std::vector<float>(n), std::vector<float>(n), std::vector<float>(n), std::vector<float>(n)};
  s.sample(seed, step, 0, n, o.x.data(), o.y.data(), o.z.data(), o.t.data());
  return o;
}

// Options for a buffer of `blocks` blocks of `bd` voxels, `refresh` replaced per step.
OutOfCoreOptions buffer_of(Int3 bd, int64_t blocks, int64_t refresh, int io_threads = 16) {
  OutOfCoreOptions o;
  o.block_dims = bd;
  o.blocks = blocks;
  o.refresh = refresh;
  o.io_threads = io_threads;
  return o;
}

}  // namespace

TEST(OutOfCore, DefaultBlockShapeHoldsAbout64KiB) {
  Int3 b = default_block_dims(Int3{2048, 2048, 1600}, DType::Float32);
  EXPECT_EQ(b.x, 256);
  EXPECT_EQ(b.y, 8);
  EXPECT_EQ(b.z, 8);
  EXPECT_EQ(b.count() * 4, 65536u);
  Int3 u8 = default_block_dims(Int3{2048, 2048, 1600}, DType::UInt8);
  EXPECT_EQ(u8.count(), 65536u);
  Int3 small = default_block_dims(Int3{20, 3, 40}, DType::UInt16);  // clamped to the volume
  EXPECT_EQ(small.x, 20);
  EXPECT_EQ(small.y, 3);
}

// Every sample's target equals the in-memory lookup at its coordinate bit for bit, including
// samples within half a voxel of a block face (which interpolate with the ghost layer) and on the
// volume's border (clamp-to-edge ghosts); coordinates stay in [0,1).
TEST(OutOfCore, BlockLookupEqualsFullVolumeIncludingGhostVoxels) {
  const Int3 d{37, 29, 23};
  const std::string json = write_u16_volume("ghost", d);
  VolumeDesc desc = describe_volume(json);
  Volume vol = load_volume(desc);
  auto file = std::make_shared<RawVolumeFile>(desc, vol.lo, vol.hi, NonFinitePolicy::Error);
  OutOfCoreOptions o = buffer_of(Int3{8, 5, 4}, 40, 6, 3);
  OutOfCoreSampler s(file, 9, o);
  const GridView g = view_of(vol);
  int64_t near_face = 0, total = 0;
  for (uint64_t step = 0; step < 6; ++step) {
    s.begin_step(step);
    Samples a = draw(s, 9, step, 4096);
    for (size_t i = 0; i < a.x.size(); ++i) {
      ASSERT_GE(a.x[i], 0.f);
      ASSERT_LT(a.x[i], 1.f);
      ASSERT_EQ(a.t[i], grid_lookup(g, a.x[i], a.y[i], a.z[i])) << "sample " << i << " of step " << step;
      // Within half a voxel of an interior block face along x: interpolation reads the neighbour block.
      float px = a.x[i] * float(d.x);
      float fx = px - 8.f * std::floor(px / 8.f);
      near_face += (fx < 0.5f || fx > 7.5f);
      ++total;
    }
  }
  EXPECT_GT(near_face, total / 16);  // ~1/8 of samples use a ghost layer along x alone
  EXPECT_EQ(s.blocks_loaded(), uint64_t(40 + 5 * 6));  // initial fill + 5 completed refreshes
}

TEST(OutOfCore, ReadsStayInsideTheTimestepsBytesAndSamplesAreDeterministic) {
  const Int3 d{30, 20, 10};
  const uint64_t header = 123, frame = d.count() * 2;
  const std::string json = write_u16_volume("bounded", d, header, 3);
  for (int t : {0, 1, 2}) {
    RawOptions ro;
    ro.timestep = t;
    VolumeDesc desc = describe_volume(json, ro);
    auto file = std::make_shared<RawVolumeFile>(desc, 0, 65535, NonFinitePolicy::Error);
    OutOfCoreOptions o = buffer_of(Int3{16, 4, 4}, 30, 5, 1);
    OutOfCoreSampler a(file, 3, o);
    o.io_threads = 7;
    OutOfCoreSampler b(file, 3, o);
    for (uint64_t step = 0; step < 8; ++step) {
      a.begin_step(step);
      b.begin_step(step);
      Samples sa = draw(a, 3, step, 1000), sb = draw(b, 3, step, 1000);
      ASSERT_EQ(sa.x, sb.x);  // reader count and I/O timing never change the samples
      ASSERT_EQ(sa.t, sb.t);
    }
    // Reads stay inside this timestep's bytes, and reach both of its ends (border blocks).
    const uint64_t begin = header + uint64_t(t) * frame;
    EXPECT_EQ(file->min_read_begin(), begin);
    EXPECT_EQ(file->max_read_end(), begin + frame);
  }
}

// read_box reads runs of consecutive rows with one pread when rows are short (<= 16 KiB), one read
// per row otherwise; either way every box (interior, on the border, bigger than the volume) is the
// clamp-to-edge copy of load_volume's voxels, and reads stay inside the voxel data.
TEST(OutOfCore, ReadBoxCoalescesShortRowsAndMatchesTheVolume) {
  for (const Int3 d : {Int3{37, 11, 6}, Int3{8300, 3, 4}}) {
    const uint64_t header = 64;
    const std::string json = write_u16_volume(fmt::format("rows{}", d.x), d, header);
    VolumeDesc desc = describe_volume(json);
    Volume vol = load_volume(desc);
    RawVolumeFile file(desc, vol.lo, vol.hi, NonFinitePolicy::Error);
    const bool short_rows = d.x * 2 <= (16 << 10);
    EXPECT_EQ(file.rows_per_read(5) > 1, short_rows) << d.x;
    for (const auto& [origin, size] : {std::pair{Int3{-1, -1, -1}, Int3{d.x + 2, d.y + 2, d.z + 2}},
                                       std::pair{Int3{3, 1, 1}, Int3{9, 2, 3}},
                                       std::pair{Int3{d.x - 5, d.y - 2, d.z - 2}, Int3{7, 5, 4}},
                                       std::pair{Int3{-1, -3, 2}, Int3{4, d.y + 6, 1}}}) {
      std::vector<float> box(size.count());
      std::vector<unsigned char> scratch(file.scratch_bytes(size));
      file.read_box(origin, size, box.data(), scratch.data());
      SCOPED_TRACE(d.x);
      expect_box_is_clamped_copy(vol, origin, size, box);
    }
    EXPECT_GE(file.min_read_begin(), header);
    EXPECT_LE(file.max_read_end(), header + d.count() * 2);
  }
}

// With a clamp box, read_box reads as if the box were the volume: boxes inside it, across its faces,
// around it whole and reaching past the volume itself repeat its edge voxels, and only its voxels are read.
TEST(OutOfCore, ReadBoxWithAClampBoxReadsOnlyThatBox) {
  for (const Int3 d : {Int3{37, 11, 6}, Int3{8300, 3, 4}}) {
    const uint64_t header = 64;
    const std::string json = write_u16_volume(fmt::format("clamp{}", d.x), d, header);
    VolumeDesc desc = describe_volume(json);
    Volume vol = load_volume(desc);
    const Box3 c{{2, 1, 1}, {d.x - 3, d.y - 1, d.z - 1}};
    for (const auto& [origin, size] : {std::pair{Int3{-4, -1, -2}, Int3{d.x + 8, d.y + 2, d.z + 4}},
                                       std::pair{Int3{3, 1, 1}, Int3{9, 2, 3}},
                                       std::pair{Int3{d.x - 6, d.y - 3, d.z - 3}, Int3{7, 5, 4}},
                                       std::pair{Int3{0, 0, 0}, Int3{3, 1, 1}}}) {
      RawVolumeFile file(desc, vol.lo, vol.hi, NonFinitePolicy::Error);
      std::vector<float> box(size.count());
      std::vector<unsigned char> scratch(file.scratch_bytes(size));
      file.read_box(origin, size, box.data(), scratch.data(), c);
      SCOPED_TRACE(fmt::format("{} at {},{},{}", d.x, origin.x, origin.y, origin.z));
      expect_box_is_clamped_copy(vol, origin, size, box, c);
      EXPECT_GE(file.min_read_begin(), header + 2 * uint64_t((c.lo.z * d.y + c.lo.y) * d.x + c.lo.x));
      EXPECT_LE(file.max_read_end(), header + 2 * uint64_t(((c.hi.z - 1) * d.y + c.hi.y - 1) * d.x + c.hi.x));
    }
    RawVolumeFile file(desc, vol.lo, vol.hi, NonFinitePolicy::Error);
    std::vector<float> one(1);
    std::vector<unsigned char> scratch(file.scratch_bytes(Int3{1, 1, 1}));
    for (const Box3& bad : {Box3{{0, 0, 0}, {d.x + 1, d.y, d.z}}, Box3{{1, 1, 1}, {1, 2, 2}}})
      EXPECT_THROW(file.read_box(Int3{0, 0, 0}, Int3{1, 1, 1}, one.data(), scratch.data(), bad), Error);
  }
}

// S defaults to R/4 (the paper's R/64 turns small buffers over too slowly; docs/benchmarks.md
// "Out-of-core training"), capped at the
// paper's 1,024 blocks per step so a large buffer does not multiply the reads per step.
TEST(OutOfCore, DefaultRefreshIsAQuarterOfTheBufferAtMostThePapersS) {
  EXPECT_EQ(OutOfCoreSampler::default_refresh(3), 1);
  EXPECT_EQ(OutOfCoreSampler::default_refresh(40), 10);
  EXPECT_EQ(OutOfCoreSampler::default_refresh(4096), 1024);
  EXPECT_EQ(OutOfCoreSampler::default_refresh(65536), 1024);
}

TEST(OutOfCore, BufferStaysInsideTheMemoryBudget) {
  const Int3 d{64, 64, 64};
  const std::string json = write_u16_volume("budget", d);
  VolumeDesc desc = describe_volume(json);
  auto file = std::make_shared<RawVolumeFile>(desc, 0, 65535, NonFinitePolicy::Error);
  for (uint64_t budget : {uint64_t(64) << 10, uint64_t(200) << 10, uint64_t(1) << 20}) {
    OutOfCoreOptions o;
    o.memory_budget = budget;
    o.block_dims = Int3{16, 4, 4};
    OutOfCoreSampler s(file, 1, o);
    EXPECT_LE(s.bytes_held(), budget);
    EXPECT_GT(s.bytes_held(), budget * 3 / 4);  // and uses most of it
    EXPECT_EQ(s.refresh(), std::max<int64_t>(1, s.blocks() / 4));
    EXPECT_EQ(s.refresh(), OutOfCoreSampler::default_refresh(s.blocks()));
  }
  OutOfCoreOptions tiny;
  tiny.memory_budget = 4096;
  try {
    OutOfCoreSampler s(file, 1, tiny);
    FAIL() << "a budget below one block must be refused";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("memory budget"), std::string::npos) << e.what();
  }
}

// mmap sampling is in-core sampling read through a memory map: same coordinates, same targets.
TEST(Mmap, SamplesEqualInCoreSampler) {
  const Int3 d{33, 17, 21};
  const std::string json = write_u16_volume("mmap", d, 77);
  VolumeDesc desc = describe_volume(json);
  Volume vol = load_volume(desc);
  MmapSampler m(std::make_shared<MappedVolume>(desc, vol.lo, vol.hi, NonFinitePolicy::Error));
  InCoreSampler in(vol);
  m.begin_step(4);
  Samples a = draw(m, 11, 4, 3000), b = draw(in, 11, 4, 3000);
  EXPECT_EQ(a.x, b.x);
  EXPECT_EQ(a.t, b.t);
}

// Float data normalises through load_volume's float(v - pivot) step (sample_io.h), which can round
// differently from (v - lo) / (hi - lo) in double. Box reads and mapped lookups must follow it: bit
// for bit equal to load_volume / grid_lookup, with the data's range (pivot = the first sample) and
// with a sidecar range (pivot = its lo), in either byte order.
TEST(OutOfCore, FloatDataReadsBitIdenticalToLoadVolume) {
  const Int3 d{13, 9, 7};
  int k = 0;
  for (DType dtype : {DType::Float32, DType::Float64})
    for (bool big : {false, true})
      for (bool with_range : {false, true}) {
        const std::string name = "float_" + std::to_string(k++);
        SCOPED_TRACE(name + ": " + dtype_name(dtype) + (big ? " big" : " little") + (with_range ? " range" : ""));
        // Values over a wide range with fractional parts, so float(v - pivot) drops bits of v.
        std::mt19937 rng{uint32_t(k)};
        std::string bytes;
        for (uint64_t i = 0; i < d.count(); ++i) {
          const double v = -5000.0 + 35000.0 * double(rng()) / 4294967296.0;
          unsigned char b[8];
          const size_t n = dtype_size(dtype);
          if (dtype == DType::Float32) {
            const float f = float(v);
            std::memcpy(b, &f, 4);
          } else {
            std::memcpy(b, &v, 8);
          }
          if (big) std::reverse(b, b + n);
          bytes.append(reinterpret_cast<const char*>(b), n);
        }
        write_file_atomic(temp_dir("vnr_ooc") + "/" + name + ".raw", bytes);
        const std::string json = temp_dir("vnr_ooc") + "/" + name + ".json";
        write_file_atomic(json, fmt::format(R"({{"file": "{}.raw", "dims": [{}, {}, {}], "dtype": "{}", )"
                                            R"("byte_order": "{}"{}}})",
                                            name, d.x, d.y, d.z, dtype_name(dtype), big ? "big" : "little",
                                            with_range ? R"(, "value_range": [-6000.1, 31000.7])" : ""));
        VolumeDesc desc = describe_volume(json);
        Volume vol = load_volume(desc);
        // The test discriminates: (v - lo) / (hi - lo) in double differs from load_volume somewhere.
        int64_t differ = 0;
        const double inv = 1.0 / (vol.hi - vol.lo);
        for (uint64_t i = 0; i < d.count(); ++i) {
          unsigned char b[8];
          const size_t n = dtype_size(dtype);
          std::memcpy(b, bytes.data() + i * n, n);
          if (big) std::reverse(b, b + n);
          float f;
          double v;
          if (dtype == DType::Float32) std::memcpy(&f, b, 4), v = f;
          else std::memcpy(&v, b, 8);
          const double u = (v - vol.lo) * inv;
          differ += float(std::clamp(u, 0.0, 1.0)) != vol.data[i];
        }
        EXPECT_GT(differ, 0);

        // A box with a ghost layer on every side: clamp-to-edge copies of load_volume's voxels.
        RawVolumeFile file(desc, vol.lo, vol.hi, NonFinitePolicy::Error);
        const Int3 size{d.x + 2, d.y + 2, d.z + 2};
        std::vector<float> box(size.count());
        std::vector<unsigned char> scratch(file.scratch_bytes(size));
        file.read_box(Int3{-1, -1, -1}, size, box.data(), scratch.data());
        expect_box_is_clamped_copy(vol, Int3{-1, -1, -1}, size, box);

        MappedVolume mapped(desc, vol.lo, vol.hi, NonFinitePolicy::Error);
        const GridView g = view_of(vol);
        std::mt19937 prng(7);
        const int n = 4000;
        std::vector<float> x(n), y(n), z(n), got(n);
        for (int i = 0; i < n; ++i) {
          x[i] = float(prng()) / 4294967296.f;
          y[i] = float(prng()) / 4294967296.f;
          z[i] = float(prng()) / 4294967296.f;
        }
        mapped.lookup(x.data(), y.data(), z.data(), n, got.data());
        for (int i = 0; i < n; ++i) {
          const float want = grid_lookup(g, x[i], y[i], z[i]);
          ASSERT_EQ(std::memcmp(&got[i], &want, sizeof(float)), 0) << "lookup " << i;
        }
      }
}

// Training with a memory budget of 1/4 of the volume's float copy (the buffer holds a small
// fraction of the voxels at a time) and the default refresh converges like in-core training: the
// mean loss of the last 50 steps within 1.25x of in-core's and the PSNR within 2.5 dB, with room
// above the gap a correct sampler leaves on this short run. (The paper's refresh of blocks/64 turns
// the buffer over too slowly for a run this short and would miss the bound.)
TEST(OutOfCore, LossCurveMatchesInCoreWithinTolerance) {
  const std::string json = temp_dir("vnr_ooc") + "/noise64.json";
  synth_volume("noise", Int3{64, 64, 64}, json, 3);
  VolumeDesc desc = describe_volume(json);
  Volume vol = load_volume(desc);
  auto train = [&](std::shared_ptr<Sampler> sampler, std::vector<float>* hist) {
    Network net(load_config("small"));
    net.init_params(7);
    CpuTrainer t(net, std::move(sampler), TrainOptions{4096, 7});
    for (int i = 0; i < 1000; ++i) t.step();
    *hist = t.loss_history();
    return evaluate(net, vol, false).psnr;
  };
  auto tail_mean = [](const std::vector<float>& h) {
    double s = 0;
    for (size_t i = h.size() - 50; i < h.size(); ++i) s += h[i];
    return s / 50;
  };
  std::vector<float> h_in, h_ooc;
  double psnr_in = train(std::make_shared<InCoreSampler>(vol), &h_in);
  auto file = std::make_shared<RawVolumeFile>(desc, vol.lo, vol.hi, NonFinitePolicy::Error);
  OutOfCoreOptions o;
  o.memory_budget = vol.dims.count() * sizeof(float) / 4;
  o.block_dims = Int3{16, 4, 4};
  auto ooc = std::make_shared<OutOfCoreSampler>(file, 7, o);
  double psnr_ooc = train(ooc, &h_ooc);
  EXPECT_LE(ooc->bytes_held(), o.memory_budget);
  EXPECT_NEAR(tail_mean(h_ooc) / tail_mean(h_in), 1.0, 0.25) << tail_mean(h_ooc) << " vs " << tail_mean(h_in);
  EXPECT_NEAR(psnr_ooc, psnr_in, 2.5);
  EXPECT_LE(file->max_read_end(), desc.offset + vol.dims.count() * 4);
}

TEST(OutOfCore, FileThatChangesOrDisappearsIsAClearError) {
  const Int3 d{32, 16, 16};
  for (std::string what : {"truncated", "deleted", "replaced"}) {
    const std::string json = write_u16_volume("change_" + what, d);
    VolumeDesc desc = describe_volume(json);
    auto file = std::make_shared<RawVolumeFile>(desc, 0, 65535, NonFinitePolicy::Error);
    OutOfCoreOptions o = buffer_of(Int3{16, 4, 4}, 8, 2);
    OutOfCoreSampler s(file, 1, o);
    MmapSampler m(std::make_shared<MappedVolume>(desc, 0, 65535, NonFinitePolicy::Error));
    s.begin_step(0);
    m.begin_step(0);
    if (what == "truncated") fs::resize_file(desc.path, d.count());
    if (what == "deleted") fs::remove(desc.path);
    if (what == "replaced") {
      write_file_atomic(desc.path + ".new", std::string(d.count() * 2, '\0'));
      fs::rename(desc.path + ".new", desc.path);
    }
    const char* expect = what == "truncated" ? "changed size" : (what == "deleted" ? "disappeared" : "replaced");
    for (Sampler* sampler : {static_cast<Sampler*>(&s), static_cast<Sampler*>(&m)}) {
      try {
        sampler->begin_step(1);
        FAIL() << what << ": no error";
      } catch (const std::exception& e) {
        EXPECT_NE(std::string(e.what()).find(expect), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find(desc.path), std::string::npos) << e.what();
      }
    }
  }
}

TEST(OutOfCore, GzipDataIsRefusedWithAClearError) {
  VolumeDesc desc;
  desc.path = "x.nrrd";
  desc.dims = Int3{4, 4, 4};
  desc.encoding = "gzip";
  try {
    RawVolumeFile f(desc, 0, 1, NonFinitePolicy::Error);
    FAIL();
  } catch (const std::exception& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("out-of-core sampling"), std::string::npos) << msg;
    EXPECT_NE(msg.find("needs uncompressed data (raw, or NRRD with 'encoding: raw')"), std::string::npos) << msg;
    EXPECT_EQ(msg.find("vnr convert"), std::string::npos) << msg;  // it converts models, not volumes
  }
}

// From the CLI: the volume file disappears while `vnr train --sampler outofcore` runs; the run
// stops with one clear error line, and the model trained so far is on disk and loads.
TEST(OutOfCoreCli, VolumeDeletedDuringTrainingKeepsTheModel) {
  const std::string json = temp_dir("vnr_ooc") + "/vanish.json", model = temp_dir("vnr_ooc") + "/vanish.vnr";
  synth_volume("noise", Int3{48, 48, 48}, json, 2);
  Result r;
  std::thread runner([&] {
    r = run("train " + json + " -o " + model +
            " --config small --batch 4096 --seconds 120 --sampler outofcore --memory-budget 64KiB "
            "--block-dims 16,4,4 --checkpoint-every 5 -q");
  });
  // Wait for the first checkpoint (training is under way), then delete the data.
  auto t0 = std::chrono::steady_clock::now();
  while (!file_exists(model) && std::chrono::steady_clock::now() - t0 < std::chrono::seconds(60))
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  ASSERT_TRUE(file_exists(model));
  fs::remove(strip_extension(json) + ".raw");
  runner.join();
  EXPECT_GT(r.code, 0) << "exits normally, with a failure status";
  const std::string& msg = r.err;
  EXPECT_NE(msg.find("disappeared during training"), std::string::npos) << msg;
  EXPECT_NE(msg.find("was saved to"), std::string::npos) << msg;
  EXPECT_EQ(std::count(msg.begin(), msg.end(), '\n'), 1) << msg;
  Model m = load_model(model);
  EXPECT_GE(m.training["steps"].get<int64_t>(), 5);
  EXPECT_TRUE(m.training.contains("error"));
}

// A run too short for the buffer to see the whole volume says so, with a --refresh that fixes it;
// the expected coverage matches a simulation of uniform block draws with replacement.
TEST(OutOfCoreCli, WarnsWhenTheRunCannotCoverTheVolume) {
  TmpDir tmp;
  const std::string json = tmp / "cover.json";
  synth_volume("noise", Int3{64, 64, 64}, json, 2);
  const std::string base = "train " + json + " -o " + (tmp / "m.vnr") +
                           " --config small --batch 1024 --sampler outofcore --memory-budget 256KiB --block-dims 16,4,4 "
                           "--eval-samples 0 ";
  Result r = run(base + "--steps 100");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.err.find("regions never loaded are not learned; --refresh"), std::string::npos) << r.err;
  r = run(base + "--steps 400 --refresh 30");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(r.err.find("regions never loaded"), std::string::npos) << r.err;

  VolumeDesc desc = describe_volume(json);
  auto file = std::make_shared<RawVolumeFile>(desc, 0, 1, NonFinitePolicy::Error);
  OutOfCoreOptions o = buffer_of(Int3{16, 4, 4}, 100, 7);
  OutOfCoreSampler s(file, 1, o);
  const int64_t n = s.volume_blocks(), draws = 100 + 7 * 50;
  std::mt19937 rng(3);
  double mean = 0;
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<char> seen(size_t(n), 0);
    for (int64_t d = 0; d < draws; ++d) seen[rng() % n] = 1;
    mean += double(std::count(seen.begin(), seen.end(), 1)) / double(n) / 200;
  }
  EXPECT_NEAR(s.expected_coverage(50), mean, 0.01);
}

// Compressed data cannot be read at random offsets: refused before any pass over the data.
TEST(OutOfCoreCli, CompressedDataIsRefusedUpFront) {
  TmpDir tmp;
  const std::string nrrd = tmp / "g.nrrd";
  std::string header = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 8 8 8\nencoding: gzip\n\n";
  write_gzip(tmp / "body.gz", std::string(512, '\x05'));
  write_bytes(nrrd, header + read_file(tmp / "body.gz"));
  for (const char* s : {"outofcore", "mmap"})
    expect_error("train " + nrrd + " -o " + (tmp / "m.vnr") + " --sampler " + s,
                 std::string("--sampler ") + s + " reads voxels at random offsets");
}

// --grid-lr-scale: the configured rate by default, the buffer's share of the volume (at least 0.1)
// with auto, or a given factor; the model records the rate it was trained with.
TEST(OutOfCoreCli, GridLearningRateScale) {
  TmpDir tmp;
  const std::string json = tmp / "lr.json", model = tmp / "lr.vnr";
  synth_volume("noise", Int3{64, 64, 64}, json, 2);
  const std::string base = "train " + json + " -o " + model +
                           " --config small --batch 1024 --steps 2 --sampler outofcore --block-dims 16,4,4 "
                           "--eval-samples 0 -q ";
  auto factor = [&]() {
    Json j = Json::parse(run("info --json " + model).out);
    return j["config"]["optimizer"]["nested"]["non_matrix_learning_rate_factor"].get<double>();
  };
  ASSERT_EQ(run(base + "--memory-budget 512KiB").code, 0);
  EXPECT_NEAR(factor(), 1.0, 1e-6);
  // 512 KiB holds 200 blocks of 16x4x4 (18x6x6 stored): R = 160 resident + S = 40 being loaded,
  // 160 * 256 / 64^3 = 0.16 of the volume.
  ASSERT_EQ(run(base + "--memory-budget 512KiB --grid-lr-scale auto").code, 0);
  EXPECT_NEAR(factor(), 160.0 * 256 / (64 * 64 * 64), 0.01);
  ASSERT_EQ(run(base + "--memory-budget 128KiB --grid-lr-scale auto").code, 0);  // 0.05: the floor
  EXPECT_NEAR(factor(), 0.1, 1e-6);
  ASSERT_EQ(run(base + "--memory-budget 512KiB --grid-lr-scale 0.5").code, 0);
  EXPECT_NEAR(factor(), 0.5, 1e-6);
  expect_error(base + "--memory-budget 512KiB --grid-lr-scale fast", "--grid-lr-scale");
  expect_error("train " + json + " -o " + model + " --grid-lr-scale 0.5", "--sampler outofcore");
}
