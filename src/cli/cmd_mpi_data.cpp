// `mpirun -n N vnr decode|eval MODEL_DIR ...` of a multi-brick model: each rank takes a run of consecutive
// bricks (balanced by voxels) and loads them and their neighbours. Decode writes the voxels they own
// into one output file at their offsets (committed atomically); eval evaluates them (errors, and the
// SSIM windows starting in them) and the ranks' sums are added up.
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
#include "vnr/fileio.h"
#include "vnr/threads.h"
#include "vnr/units.h"
#include "vnr/volume_writer.h"

namespace vnr::cli {

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// This rank's share (BrickShare, vnr/bricks.h), its networks at the asked precision.
BrickShare open_rank_share(const std::string& dir, Int3 dims, int reach, const std::string& precision) {
  if (!is_bricked_model_dir(dir))
    fail("'{}' is not a multi-brick model directory (manifest.json): under mpirun, decode, eval and render run "
         "over the bricks of a model trained with --bricks; run a single model without mpirun", dir);
  BrickShare share = open_brick_share(dir, dims, reach, mpi::rank(), mpi::size());
  set_inference_precision(*share.model, parse_precision(precision));
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
  BrickShare share;
  Int3 dims;
  DType out_t = DType::Float32;
  mpi::agree("to open the model", [&] {
    check_no_overwrite(volume_output_files(a.output), a.force);
    const std::vector<int> none;
    const std::shared_ptr<BrickedModel> header = is_bricked_model_dir(a.model) ? load_bricked_model(a.model, &none) : nullptr;
    dims = a.dims.empty() && header ? header->plan.dims : a.dims.empty() ? Int3{1, 1, 1} : parse_dims(a.dims);
    share = open_rank_share(a.model, dims, 1, a.precision);  // 1: the trilinear reach of resampling
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
  BrickShare share;
  VolumeDesc desc;
  ValueRange range;
  std::string range_source;
  mpi::agree("to open the model and the volume", [&] {
    desc = describe_volume(a.volume, a.vol.raw());
    // SSIM windows starting in a brick reach 6 voxels past it.
    share = open_rank_share(a.model, desc.dims, a.no_ssim ? 1 : 7, a.precision);
    const Int3 md = share.model->plan.dims;
    if (!(desc.dims == md))
      fail("'{}' has {}x{}x{} voxels but the model {}x{}x{}", a.volume, desc.dims.x, desc.dims.y, desc.dims.z, md.x, md.y,
           md.z);
  });
  // The range `vnr eval` normalises the volume with (its sidecar's, else one scan, on rank 0).
  mpi::agree("to find the volume's value range", [&] {
    if (mpi::rank() != 0) return;
    const FileEvalPlan plan = plan_file_evaluation(desc, 0, false);
    range = file_evaluation_range(plan, model_of_bricks(share.model), false, a.vol.load(), &range_source);
  });
  const std::string bytes = mpi::broadcast(std::string(reinterpret_cast<const char*>(&range), sizeof range));
  std::memcpy(&range, bytes.data(), sizeof range);
  const auto t0 = std::chrono::steady_clock::now();
  EvalSums mine;
  mpi::agree("evaluating", [&] {
    mine = evaluate_regions(model_of_bricks(share.model), desc, range, a.vol.load().non_finite, share.regions,
                            !a.no_ssim);
  });
  EvalSums all;
  all.sse = mpi::sum(mine.sse);
  all.voxels = mpi::sum(mine.voxels);
  all.max_abs_error = mpi::max(mine.max_abs_error);
  all.ssim_sum = mpi::sum(mine.ssim_sum);
  all.ssim_windows = mpi::sum(mine.ssim_windows);
  const EvalResult ev = all.result(range.hi - range.lo);
  const double seconds = mpi::max(seconds_since(t0)), most_loaded = mpi::max(double(share.loaded));
  if (mpi::rank() != 0) return;
  std::printf("PSNR %.2f dB", ev.psnr);
  if (!a.no_ssim) std::printf(", SSIM %.4f", ev.ssim);
  std::printf(", max |error| %.4g (%.4g in data units), evaluated in %.2fs on %d ranks (a rank loaded at most %.0f of "
              "%zu bricks)\n",
              ev.max_abs_error, ev.max_abs_error_original, seconds, mpi::size(), most_loaded,
              share.model->plan.bricks.size());
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
