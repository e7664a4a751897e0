// `mpirun -n N vnr decode|eval MODEL_DIR ...` of a multi-brick model. Decode: each rank takes a run of
// consecutive bricks (balanced by voxels), loads them and their neighbours, and writes the voxels they
// own into one output file at their offsets (committed atomically). Eval: each rank takes an even share
// of the z-slices, loads the bricks they touch, and the ranks' error and SSIM sums are added up.
#ifdef VNR_HAVE_MPI
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include "mpi/comm.h"
#include "mpi/parallel_file.h"
#include "cli.h"
#include "mpi_cli.h"
#include "vnr/bricks.h"
#include "vnr/core/fileio.h"
#include "vnr/core/parallel.h"
#include "vnr/core/units.h"
#include "vnr/volume/raw_access.h"
#include "vnr/volume/writer.h"

namespace vnr::cli {

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// The z-slices [z0, z1) of `depth` that rank r of n takes.
std::pair<int64_t, int64_t> my_slices(int64_t depth) {
  const int64_t r = mpi::rank(), n = mpi::size();
  return {depth * r / n, depth * (r + 1) / n};
}

// The plan of MODEL_DIR and this rank's bricks for output slices [z0, z1) of an out_dims grid.
std::shared_ptr<BrickedModel> open_my_bricks(const std::string& dir, Int3 out_dims, int64_t z0, int64_t z1,
                                             const std::string& precision) {
  if (!is_bricked_model_dir(dir))
    fail("'{}' is not a multi-brick model directory (manifest.json): under mpirun, decode, eval and render run "
         "over the bricks of a model trained with --bricks; run a single model without mpirun", dir);
  const std::vector<int> none;
  const BrickPlan plan = load_bricked_model(dir, &none)->plan;
  // The slices' extent in the model's grid, one voxel wider for the trilinear reach of resampling.
  const double scale = double(plan.dims.z) / double(out_dims.z);
  Box3 region{{0, 0, std::max<int64_t>(0, int64_t(std::floor(z0 * scale)) - 1)},
              {plan.dims.x, plan.dims.y, std::min<int64_t>(plan.dims.z, int64_t(std::ceil(z1 * scale)) + 1)}};
  const std::vector<int> only = z1 > z0 ? bricks_touching(plan, region) : none;
  std::shared_ptr<BrickedModel> m = load_bricked_model(dir, &only);
  for (std::optional<Model>& b : m->bricks)
    if (b) b->net->set_inference_precision(parse_precision(precision));
  return m;
}

// This rank's bricks for decoding at `dims` (contiguous_bricks), their output regions, and the model with
// those bricks and their neighbours loaded.
struct DecodeShare {
  std::shared_ptr<BrickedModel> model;
  std::vector<Box3> regions;
  size_t loaded = 0;  // bricks loaded
};
DecodeShare open_decode_share(const std::string& dir, Int3 dims, const std::string& precision) {
  if (!is_bricked_model_dir(dir))
    fail("'{}' is not a multi-brick model directory (manifest.json): under mpirun, decode, eval and render run "
         "over the bricks of a model trained with --bricks; run a single model without mpirun", dir);
  const std::vector<int> none;
  const BrickPlan plan = load_bricked_model(dir, &none)->plan;
  DecodeShare share;
  std::vector<int> only;
  for (int b : contiguous_bricks(plan, mpi::rank(), mpi::size())) {
    const Box3 region = brick_output_region(plan, b, dims);
    if (region.empty()) continue;
    share.regions.push_back(region);
    // The bricks blended in its owned box, one voxel wider for the trilinear reach of resampling.
    Box3 reach = plan.bricks[size_t(b)].owned;
    for (int a = 0; a < 3; ++a) {
      reach.lo[a] = std::max<int64_t>(0, reach.lo[a] - 1);
      reach.hi[a] = std::min<int64_t>(plan.dims[a], reach.hi[a] + 1);
    }
    for (int n : bricks_touching(plan, reach)) only.push_back(n);
  }
  std::sort(only.begin(), only.end());
  only.erase(std::unique(only.begin(), only.end()), only.end());
  share.loaded = only.size();
  share.model = load_bricked_model(dir, &only);
  for (std::optional<Model>& b : share.model->bricks)
    if (b) b->net->set_inference_precision(parse_precision(precision));
  return share;
}

struct DecodeMpiArgs {
  std::string model, output, dims, dtype = "float32", precision = "auto";
  int threads = 0;
  bool quiet = false, force = false;
};

// Decodes region of the dims grid in z-chunks of about 16 M voxels and writes it into file at its
// offsets: a z-slice's rows together when the region spans the grid's width, else row by row.
void write_region(mpi::ParallelFile& file, uint64_t data_offset, const BrickedModel& m, Int3 dims, const Box3& region,
                  DType out_t) {
  const Int3 r = region.size();
  const size_t esize = dtype_size(out_t);
  const int64_t chunk = std::max<int64_t>(1, (int64_t(1) << 24) / (r.x * r.y));
  const bool whole_rows = r.x == dims.x;
  std::vector<float> values;
  std::vector<unsigned char> bytes;
  for (int64_t za = region.lo.z; za < region.hi.z; za += chunk) {
    const Box3 part{{region.lo.x, region.lo.y, za}, {region.hi.x, region.hi.y, std::min(region.hi.z, za + chunk)}};
    values.resize(part.voxels());
    decode_bricked_region(m, dims, part, values.data());
    for (float& v : values) v = float(m.lo + double(v) * (m.hi - m.lo));  // to_original_units
    bytes.resize(values.size() * esize);
    store_values(out_t, values.data(), int64_t(values.size()), bytes.data());
    const Int3 ps = part.size();
    for (int64_t z = 0; z < ps.z; ++z)
      for (int64_t y = 0; y < ps.y; y += whole_rows ? ps.y : 1) {
        const int64_t rows = whole_rows ? ps.y : 1;
        const uint64_t voxel = uint64_t(((part.lo.z + z) * dims.y + part.lo.y + y) * dims.x + part.lo.x);
        file.write_at(data_offset + voxel * esize, bytes.data() + size_t((z * ps.y + y) * ps.x) * esize,
                      size_t(rows * ps.x) * esize);
      }
  }
}

void run_decode_mpi(const DecodeMpiArgs& a) {
  DecodeShare share;
  Int3 dims;
  DType out_t = DType::Float32;
  mpi::agree("to open the model", [&] {
    check_no_overwrite(volume_output_files(a.output), a.force);
    const std::vector<int> none;
    const std::shared_ptr<BrickedModel> header = is_bricked_model_dir(a.model) ? load_bricked_model(a.model, &none) : nullptr;
    dims = a.dims.empty() && header ? header->plan.dims : a.dims.empty() ? Int3{1, 1, 1} : parse_dims(a.dims);
    share = open_decode_share(a.model, dims, a.precision);
    out_t = a.dtype == "source" ? share.model->source_dtype : parse_dtype(a.dtype);
  });
  const BrickedModel& m = *share.model;
  const auto t0 = std::chrono::steady_clock::now();
  // As `vnr decode` writes it: voxel size relative to the model's grid, the model's value range.
  const Vec3f spacing{float(double(m.plan.dims.x) / dims.x), float(double(m.plan.dims.y) / dims.y),
                      float(double(m.plan.dims.z) / dims.z)};
  const std::string header = volume_file_header(a.output, dims, out_t, spacing);
  mpi::ParallelFile file(a.output, header.size() + uint64_t(dims.count()) * dtype_size(out_t));
  mpi::agree("decoding", [&] {
    if (mpi::rank() == 0 && !header.empty()) file.write_at(0, header.data(), header.size());
    for (const Box3& region : share.regions) write_region(file, header.size(), m, dims, region, out_t);
  });
  file.commit();
  mpi::agree("to write the sidecar", [&] {
    const std::vector<std::string> files = volume_output_files(a.output);
    if (mpi::rank() == 0 && files.size() > 1)
      write_file_atomic(files[1], raw_sidecar_text(a.output, dims, out_t, spacing, std::make_pair(m.lo, m.hi)));
  });
  const double seconds = mpi::max(seconds_since(t0));
  const double most_loaded = mpi::max(double(share.loaded));
  if (mpi::rank() == 0)
    std::printf("decoded %lldx%lldx%lld %s to %s in %.2fs (%d ranks; a rank loaded at most %.0f of %zu bricks)\n",
                (long long)dims.x, (long long)dims.y, (long long)dims.z, dtype_name(out_t), a.output.c_str(), seconds,
                mpi::size(), most_loaded, m.plan.bricks.size());
}

struct EvalMpiArgs {
  std::string model, volume, report, precision = "auto";
  int threads = 0;
  bool quiet = false, no_ssim = false;
  VolumeArgs vol;
};

void run_eval_mpi(const EvalMpiArgs& a) {
  std::shared_ptr<BrickedModel> m;
  VolumeDesc desc;
  ValueRange range;
  std::string range_source;
  int64_t z0 = 0, z1 = 0;
  mpi::agree("to open the model and the volume", [&] {
    desc = describe_volume(a.volume, a.vol.raw());
    std::tie(z0, z1) = my_slices(desc.dims.z);
    // SSIM windows starting in the last slices reach 6 slices further.
    m = open_my_bricks(a.model, desc.dims, z0, a.no_ssim || z1 == z0 ? z1 : std::min(desc.dims.z, z1 + 6), a.precision);
    if (!(desc.dims == m->plan.dims))
      fail("'{}' has {}x{}x{} voxels but the model {}x{}x{}", a.volume, desc.dims.x, desc.dims.y, desc.dims.z,
           m->plan.dims.x, m->plan.dims.y, m->plan.dims.z);
  });
  // The range `vnr eval` normalises the volume with (its sidecar's, else one scan, on rank 0).
  mpi::agree("to find the volume's value range", [&] {
    if (mpi::rank() != 0) return;
    const FileEvalPlan plan = plan_file_evaluation(desc, 0, false);
    range = file_evaluation_range(plan, model_of_bricks(m), false, a.vol.load(), &range_source);
  });
  const std::string bytes = mpi::broadcast(std::string(reinterpret_cast<const char*>(&range), sizeof range));
  std::memcpy(&range, bytes.data(), sizeof range);
  const auto t0 = std::chrono::steady_clock::now();
  EvalSums mine;
  mpi::agree("evaluating", [&] {
    RawVolumeFile file(desc, range.lo, range.hi, a.vol.load().non_finite, "distributed evaluation",
                       "convert the volume to raw or NRRD (uncompressed)");
    mine = evaluate_box_slices(model_of_bricks(m), file, Box3{{0, 0, 0}, desc.dims}, z0, z1, !a.no_ssim);
  });
  EvalSums all;
  all.sse = mpi::sum(mine.sse);
  all.voxels = mpi::sum(mine.voxels);
  all.max_abs_error = mpi::max(mine.max_abs_error);
  all.ssim_sum = mpi::sum(mine.ssim_sum);
  all.ssim_windows = mpi::sum(mine.ssim_windows);
  const EvalResult ev = all.result(range.hi - range.lo);
  const double seconds = mpi::max(seconds_since(t0));
  if (mpi::rank() != 0) return;
  std::printf("PSNR %.2f dB", ev.psnr);
  if (!a.no_ssim) std::printf(", SSIM %.4f", ev.ssim);
  std::printf(", max |error| %.4g (%.4g in data units), evaluated in %.2fs on %d ranks\n", ev.max_abs_error,
              ev.max_abs_error_original, seconds, mpi::size());
  write_report(a.report, Json{{"psnr", ev.psnr}, {"mse", ev.mse}, {"max_abs_error", ev.max_abs_error},
                              {"max_abs_error_original", ev.max_abs_error_original}, {"samples", desc.dims.count()},
                              {"decode_seconds", seconds}, {"ranks", mpi::size()}, {"value_range", {range.lo, range.hi}},
                              {"value_range_source", range_source},
                              {"ssim", a.no_ssim ? Json(nullptr) : Json(ev.ssim)}});
}

}  // namespace

void add_decode_mpi(CLI::App& app) {
  auto a = std::make_shared<DecodeMpiArgs>();
  CLI::App* c = app.add_subcommand("decode", "decode a multi-brick model, each rank its slabs of one file (under mpirun)");
  c->add_option("model", a->model, "multi-brick model directory")->required();
  c->add_option("-o,--output", a->output, "OUT.raw (with OUT.json sidecar) or OUT.nrrd, in a directory every rank sees")->required();
  c->add_option("--dims", a->dims, "output resolution X,Y,Z (default: the model's)");
  c->add_option("--dtype", a->dtype, "float32, or 'source' for the original data type")->capture_default_str();
  c->add_option("--threads", a->threads, "CPU threads per rank (default: the node's cores / its ranks)");
  c->add_flag("-q,--quiet", a->quiet, "no progress output");
  c->add_flag("--force", a->force, "replace existing output files");
  add_precision_option(c, a->precision);
  c->callback([a] {
    set_num_threads(rank_threads(a->threads));
    run_decode_mpi(*a);
  });
}

void add_eval_mpi(CLI::App& app) {
  auto a = std::make_shared<EvalMpiArgs>();
  CLI::App* c = app.add_subcommand("eval", "PSNR and max error of a multi-brick model, each rank its slabs (under mpirun)");
  c->add_option("model", a->model, "multi-brick model directory")->required();
  c->add_option("volume", a->volume, "the ground-truth volume (uncompressed)")->required();
  c->add_option("--report", a->report, "write a JSON report (rank 0)");
  c->add_option("--threads", a->threads, "CPU threads per rank (default: the node's cores / its ranks)");
  c->add_flag("--no-ssim", a->no_ssim, "skip the SSIM (each rank then reads no slices past its own)");
  c->add_flag("-q,--quiet", a->quiet, "no progress output");
  add_precision_option(c, a->precision);
  a->vol.add(c);
  c->callback([a] {
    set_num_threads(rank_threads(a->threads));
    run_eval_mpi(*a);
  });
}

}  // namespace vnr::cli
#endif
