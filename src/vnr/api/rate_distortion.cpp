// `vnr bench rd`: vnr's rate-distortion points and ZFP's on one volume (include/vnr/rate_distortion.h).
#include "vnr/rate_distortion.h"
#include <zfp.h>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fmt/format.h>
#include <memory>
#include <unistd.h>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/metrics.h"
#include "vnr/progress.h"
#include "vnr/model.h"
#include "vnr/trainer.h"
#include "vnr/train/rate_control.h"
#include "vnr/train/session.h"

namespace vnr {

namespace {

uint64_t volume_bytes(const Volume& v) { return v.dims.count() * dtype_size(v.source_dtype); }

// PSNR and max error of decoded values (data units) against the volume (normalised).
void score(RdPoint& p, const Volume& vol, const std::vector<float>& decoded_original) {
  const double range = vol.hi - vol.lo;
  std::vector<float> u(decoded_original.size());
  for (size_t i = 0; i < u.size(); ++i) u[i] = float((double(decoded_original[i]) - vol.lo) / (range > 0 ? range : 1));
  const ErrorStats e = error_stats(vol.data.data(), u.data(), vol.dims);
  p.psnr = e.psnr;
  p.max_abs_error = e.max_abs_error * range;
  p.ratio = double(volume_bytes(vol)) / double(p.bytes);
}

using ZfpStream = std::unique_ptr<zfp_stream, void (*)(zfp_stream*)>;

// Compresses the volume (data units, float32) with a configured stream, decompresses it and scores it.
RdPoint zfp_run(const Volume& vol, const std::string& codec, double parameter, const std::function<void(zfp_stream*, zfp_field*)>& set_mode) {
  std::vector<float> data(vol.data.size());
  for (size_t i = 0; i < data.size(); ++i) data[i] = float(vol.lo + double(vol.data[i]) * (vol.hi - vol.lo));
  const auto nx = size_t(vol.dims.x), ny = size_t(vol.dims.y), nz = size_t(vol.dims.z);
  std::unique_ptr<zfp_field, void (*)(zfp_field*)> field(zfp_field_3d(data.data(), zfp_type_float, nx, ny, nz), zfp_field_free);
  ZfpStream zfp(zfp_stream_open(nullptr), zfp_stream_close);
  if (!field || !zfp) fail("zfp: cannot allocate a stream");
  set_mode(zfp.get(), field.get());
  std::vector<unsigned char> buffer(zfp_stream_maximum_size(zfp.get(), field.get()));
  std::unique_ptr<bitstream, void (*)(bitstream*)> bits(stream_open(buffer.data(), buffer.size()), stream_close);
  zfp_stream_set_bit_stream(zfp.get(), bits.get());
  RdPoint p;
  p.codec = codec;
  p.parameter = parameter;
  const auto t0 = std::chrono::steady_clock::now();
  zfp_stream_rewind(zfp.get());
  p.bytes = zfp_compress(zfp.get(), field.get());
  p.seconds = seconds_since(t0);
  if (p.bytes == 0) fail("zfp compression failed ({} {})", codec, parameter);
  std::vector<float> out(data.size());
  zfp_field_set_pointer(field.get(), out.data());
  zfp_stream_rewind(zfp.get());
  if (!zfp_decompress(zfp.get(), field.get())) fail("zfp decompression failed ({} {})", codec, parameter);
  score(p, vol, out);
  return p;
}

}  // namespace

RdPoint zfp_fixed_rate(const Volume& vol, double bits_per_value) {
  if (!(bits_per_value > 0) || bits_per_value > 32) fail("zfp rate must be in (0, 32] bits per value, got {}", bits_per_value);
  return zfp_run(vol, "zfp-rate", bits_per_value, [&](zfp_stream* z, zfp_field*) {
    zfp_stream_set_rate(z, bits_per_value, zfp_type_float, 3, zfp_false);
  });
}

RdPoint zfp_fixed_accuracy(const Volume& vol, double tolerance) {
  if (!(tolerance > 0) || !std::isfinite(tolerance)) fail("zfp tolerance must be positive, got {}", tolerance);
  return zfp_run(vol, "zfp-accuracy", tolerance, [&](zfp_stream* z, zfp_field*) { zfp_stream_set_accuracy(z, tolerance); });
}

Json RdReport::to_json() const {
  Json pts = Json::array();
  for (const RdPoint& p : points)
    pts.push_back({{"codec", p.codec},
                   {"parameter", p.parameter},
                   {"bytes", p.bytes},
                   {"ratio", p.ratio},
                   {"psnr", p.psnr},
                   {"max_abs_error", p.max_abs_error},
                   {"seconds", p.seconds},
                   {"extra", p.extra}});
  return {{"volume", volume}, {"dims", {dims.x, dims.y, dims.z}}, {"volume_bytes", volume_bytes}, {"points", pts}};
}

namespace {

// One vnr model at a target ratio, trained in a session over the shared volume, saved to `path`.
RdPoint train_point(const std::shared_ptr<const Volume>& vol, const std::string& name, double ratio,
                    const RdOptions& o, const std::string& path, Model* trained) {
  const auto t0 = std::chrono::steady_clock::now();
  TrainingSetup s;
  s.volume = name;
  s.config = o.config;
  s.target_ratio = ratio;
  s.residuals = o.residuals;
  s.seed = o.seed;
  s.device = o.device;
  s.steps = o.steps;
  s.session.output = path;
  std::unique_ptr<TrainingSession> session = open_training_session(s, vol);
  // --target-ratio's path: compact (quantized, entropy-coded) models of the exact size.
  if (session->options().compact.enabled())
    train_compact(*session, o.steps > 0 ? o.steps : -1, o.steps > 0 ? 0 : o.seconds, session->options().compact);
  else {
    session->set_budget(o.steps > 0 ? o.steps : -1, o.steps > 0 ? 0 : o.seconds);
    session->run(o.steps > 0 ? o.steps : INT64_MAX, o.steps > 0 ? 0 : o.seconds);
  }
  const TrainingResult r = session->finish({.ssim = false});
  RdPoint p;
  p.codec = "vnr";
  p.parameter = ratio;
  p.bytes = r.model_bytes;
  p.ratio = r.compression_ratio;
  p.psnr = r.psnr;
  p.max_abs_error = r.max_abs_error_original;
  p.seconds = r.seconds;
  p.extra = {{"steps", r.steps}, {"n_params", r.report["n_params"]}, {"wall_seconds", seconds_since(t0)}};
  if (r.report.contains("error_bound")) {  // --residuals auto spent part of the file on residuals
    p.extra["network_psnr"] = r.report["network_psnr"];
    p.extra["residual_bytes"] = r.report["error_bound"]["residual_bytes"];
    p.extra["max_error"] = r.report["error_bound"]["max_error"];
  }
  *trained = std::move(session->model());
  return p;
}

// The bound met on one trained network: its file plus the coded residuals.
RdPoint bound_point(const Volume& vol, const Model& m, uint64_t model_file_bytes, double rel_bound, double net_ratio) {
  const auto t0 = std::chrono::steady_clock::now();
  const double b = normalised_error_bound({0, rel_bound}, vol.lo, vol.hi, vol.source_dtype);
  Residuals res = smallest_residuals(*m.net, vol.data.data(), vol.dims, b);
  const EncodedResiduals& enc = *res.encoded;
  RdPoint p;
  p.codec = "vnr-bound";
  p.parameter = rel_bound;
  p.bytes = model_file_bytes + enc.bytes.size() + enc.meta.dump().size();
  p.seconds = seconds_since(t0);
  std::vector<float> dec(vol.data.size());
  Decoder(*m.net, Device::Cpu, &res).slices(vol.dims, 0, vol.dims.z, dec.data());
  for (float& v : dec) v = float(vol.lo + double(v) * (vol.hi - vol.lo));
  score(p, vol, dec);
  p.extra = residual_coding_summary(res);
  p.extra["network_ratio"] = net_ratio;
  p.extra["network_bytes"] = model_file_bytes;
  p.extra["bound_holds"] = p.max_abs_error <= b * (vol.hi - vol.lo);
  return p;
}

}  // namespace

RdReport run_rate_distortion(const std::string& volume_path, const Volume& volume, const RdOptions& o) {
  auto say = [&](const RdPoint& p) {
    if (o.message)
      o.message(fmt::format("{:<13} {:<8g} ratio {:8.2f}  PSNR {:6.2f} dB  max |error| {:.4g}  ({:.1f}s)", p.codec,
                            p.parameter, p.ratio, p.psnr, p.max_abs_error, p.seconds));
  };
  RdReport rep;
  rep.volume = volume_path;
  rep.dims = volume.dims;
  rep.volume_bytes = volume_bytes(volume);
  auto add = [&](RdPoint p) {
    say(p);
    rep.points.push_back(std::move(p));
  };
  for (double bpv : o.zfp_rates) add(zfp_fixed_rate(volume, bpv));
  for (double rel : o.rel_bounds) add(zfp_fixed_accuracy(volume, rel * (volume.hi - volume.lo)));
  const auto shared = std::make_shared<const Volume>(volume);
  const std::string dir = (std::filesystem::temp_directory_path() / fmt::format("vnr_rd_{}", ::getpid())).string();
  std::filesystem::create_directories(dir);
  std::vector<std::optional<RdPoint>> best(o.rel_bounds.size());
  std::vector<Json> tried(o.rel_bounds.size(), Json::array());  // every network's total, per bound
  try {
    for (double ratio : o.ratios) {
      Model trained;
      const std::string path = dir + fmt::format("/r{}.vnr", ratio);
      try {
        add(train_point(shared, volume_path, ratio, o, path, &trained));
      } catch (const BudgetBelowSmallestFile& e) {  // a small volume at a high ratio: the other points stand
        if (o.message) o.message(fmt::format("vnr           {:<8g} skipped: {}", ratio, e.what()));
        continue;
      }
      const Model m = load_model(path);  // the network as stored, as a decoder sees it
      for (size_t k = 0; k < o.rel_bounds.size(); ++k) {
        RdPoint p = bound_point(volume, m, file_size(path), o.rel_bounds[k], ratio);
        tried[k].push_back({{"network_ratio", ratio}, {"bytes", p.bytes}, {"ratio", p.ratio}});
        if (!best[k] || p.bytes < best[k]->bytes) best[k] = std::move(p);
      }
      std::filesystem::remove(path);
    }
    // PSNR against training time at one ratio: a model per budget.
    for (double t : o.times) {
      RdOptions ot = o;
      ot.seconds = t;
      ot.steps = -1;
      Model trained;
      try {
        RdPoint p = train_point(shared, volume_path, o.time_ratio, ot, dir + fmt::format("/t{}.vnr", t), &trained);
        p.codec = "vnr-time";
        p.parameter = t;
        p.extra["target_ratio"] = o.time_ratio;
        add(std::move(p));
      } catch (const BudgetBelowSmallestFile& e) {
        if (o.message) o.message(fmt::format("vnr-time      {:<8g} skipped: {}", t, e.what()));
      }
    }
  } catch (...) {
    std::filesystem::remove_all(dir);
    throw;
  }
  std::filesystem::remove_all(dir);
  for (size_t k = 0; k < best.size(); ++k)
    if (best[k]) {
      best[k]->extra["networks_tried"] = tried[k];
      add(std::move(*best[k]));
    }
  return rep;
}

}  // namespace vnr
