#include "vnr/train/training_data.h"
#include <algorithm>
#include <chrono>
#include <cmath>
#include "vnr/error.h"
#include "vnr/progress.h"
#include "vnr/volume/stream.h"
#include "vnr/units.h"

namespace vnr {
namespace {

void say(const MessageFn& message, const std::string& line) {
  if (message) message(line);
}

std::string dims_text(Int3 d) { return fmt::format("{}x{}x{}", d.x, d.y, d.z); }

// The start of the volume's line for people, up to the value range's "[".
std::string volume_line_head(const std::string& name, const TrainingData& t) {
  return fmt::format("volume {}: {} {}, {}, range [", name, dims_text(t.dims), dtype_name(t.dtype),
                     human_bytes(double(t.source_bytes())));
}

// Samples the in-memory volume `vol` in core.
void sample_in_core(TrainingData& t, std::shared_ptr<const Volume> vol) {
  t.kind = "incore";
  t.vol = std::move(vol);
  t.lo = t.vol->lo;
  t.hi = t.vol->hi;
  t.sampler = std::make_shared<InCoreSampler>(*t.vol);
}

// Regions never loaded are never learned: the note when a run cannot be expected to see (almost) the
// whole volume, with the --refresh (or steps) that would.
void note_coverage(const OutOfCoreSampler& s, int64_t steps, const std::string& what, const MessageFn& message) {
  if (steps <= 0) return;
  const double cover = s.expected_coverage(steps);
  if (cover >= 0.95) return;
  const int64_t need = int64_t(std::ceil(3.0 * double(s.volume_blocks()) / double(steps)));
  const int64_t max_refresh = std::max<int64_t>(1, s.blocks() / 2);
  const std::string fix =
      need <= max_refresh ? fmt::format("--refresh {} covers about 95%", need)
                          : fmt::format("{} steps with --refresh {} cover about 95%",
                                        int64_t(std::ceil(3.0 * double(s.volume_blocks()) / double(max_refresh))),
                                        max_refresh);
  say(message, fmt::format("note: over {} steps the buffer is expected to load only {:.0f}% of the {}'s {} "
                           "blocks, and regions never loaded are not learned; {}",
                           steps, 100 * cover, what, s.volume_blocks(), fix));
}

void open_out_of_core(TrainingData& t, const TrainingDataOptions& o, const MessageFn& message) {
  t.raw_file = std::make_shared<RawVolumeFile>(t.desc, t.lo, t.hi, t.load.non_finite);
  OutOfCoreOptions oo;
  oo.memory_budget = o.memory_budget;
  oo.blocks = o.blocks;
  oo.refresh = o.refresh;
  if (o.block_dims) oo.block_dims = *o.block_dims;
  Progress fill_bar("fill blocks", 1.0, !o.show_progress);
  oo.fill_progress = [&](double f) { fill_bar.update(f); };
  oo.region = o.region;
  t.out_of_core = std::make_shared<OutOfCoreSampler>(t.raw_file, o.seed, oo);
  const OutOfCoreSampler& s = *t.out_of_core;
  fill_bar.finish(fmt::format("({} blocks in {:.1f}s)", s.blocks(), s.fill_seconds()));
  say(message, fmt::format("out-of-core buffer: {} blocks of {} voxels, {} replaced per step; {} held of a {} budget",
                           s.blocks(), dims_text(s.block_dims()), s.refresh(), human_bytes(double(s.bytes_held())),
                           human_bytes(double(o.memory_budget))));
  note_coverage(s, o.steps, o.region.empty() ? "volume" : "region", message);
  t.sampler = t.out_of_core;
}

}  // namespace

TrainingData open_training_data(const std::string& name, const VolumeDesc& desc, const LoadOptions& load,
                                const TrainingDataOptions& o, const MessageFn& message) {
  TrainingData t;
  t.desc = desc;
  t.load = load;
  t.memory_budget = o.memory_budget;
  t.dims = o.region.empty() ? desc.dims : o.region.size();
  t.dtype = desc.dtype;
  if (!o.region.empty() && (o.sampler != "outofcore" || !o.range))
    fail("open_training_data: a region of the volume is sampled out of core with a given value range");
  const uint64_t in_core_bytes = t.dims.count() * sizeof(float);
  t.kind = o.sampler.empty() ? (in_core_bytes <= o.memory_budget ? "incore" : "outofcore") : o.sampler;
  if (t.kind != "outofcore" && (o.blocks > 0 || o.refresh > 0 || o.block_dims || o.grid_lr_scale != "1"))
    fail("--blocks, --refresh, --block-dims and --grid-lr-scale apply to --sampler outofcore (this run samples {})", t.kind);
  auto t0 = std::chrono::steady_clock::now();
  const std::string head = volume_line_head(name, t);
  if (t.kind == "incore") {
    if (in_core_bytes > o.memory_budget)
      fail("the volume needs {} in memory, more than the memory budget of {}; use --sampler outofcore (or mmap), or "
           "raise --memory-budget",
           human_bytes(double(in_core_bytes)), human_bytes(double(o.memory_budget)));
    sample_in_core(t, std::make_shared<const Volume>(load_volume(desc, load)));
    say(message, head + fmt::format("{:g}, {:g}], loaded in {:.1f}s", t.lo, t.hi, seconds_since(t0)));
    return t;
  }
  if (t.kind != "outofcore" && t.kind != "mmap") fail("unknown --sampler '{}' (allowed: incore, outofcore, mmap)", t.kind);
  // Before any pass over the data: these samplers read at random offsets.
  if (t.kind == "mmap")
    require_raw_bytes(desc, "--sampler mmap",
                      desc.encoding == "hdf5" || desc.encoding == "netcdf" ? "use --sampler outofcore" : "");
  else
    require_random_access(desc, "--sampler " + t.kind);
  // The value range: the descriptor's, or one streaming pass (the volume is never loaded).
  const bool known_range = (desc.range_lo && desc.range_hi) || o.range;
  Progress scan_bar("value range", 1.0, !o.show_progress || known_range);
  ValueRange r = o.range ? *o.range : scan_value_range(desc, load, [&](double f) { scan_bar.update(f); });
  scan_bar.finish();
  t.lo = r.lo;
  t.hi = r.hi;
  say(message, head + fmt::format("{:g}, {:g}]{}; sampled {}", t.lo, t.hi,
                                  o.range ? " (the whole volume's)" : known_range ? " (from the descriptor)"
                                              : fmt::format(" (scanned in {:.1f}s)", seconds_since(t0)),
                                  t.kind == "mmap" ? "through a memory map" : "out of core"));
  if (t.kind == "mmap") {
    t.sampler = std::make_shared<MmapSampler>(std::make_shared<MappedVolume>(desc, t.lo, t.hi, load.non_finite));
    return t;
  }
  open_out_of_core(t, o, message);
  return t;
}

TrainingData in_memory_training_data(const std::string& name, std::shared_ptr<const Volume> volume,
                                     uint64_t memory_budget, const MessageFn& message) {
  TrainingData t;
  t.memory_budget = memory_budget;
  t.dims = t.desc.dims = volume->dims;
  t.dtype = t.desc.dtype = volume->source_dtype;
  t.desc.path = name;
  sample_in_core(t, std::move(volume));
  say(message, volume_line_head(name, t) + fmt::format("{:g}, {:g}], in memory", t.lo, t.hi));
  return t;
}

ModelConfig scale_grid_learning_rate(ModelConfig config, const std::string& scale_text,
                                     const OutOfCoreSampler& s, std::string* note) {
  if (note) note->clear();
  double scale;
  if (scale_text == "auto") {
    scale = std::clamp(s.resident_fraction(), 0.1, 1.0);
  } else {
    char* end = nullptr;
    scale = std::strtod(scale_text.c_str(), &end);
    if (end == scale_text.c_str() || *end || !(scale > 0) || !std::isfinite(scale))
      fail("--grid-lr-scale expects auto or a positive number, got '{}'", scale_text);
  }
  if (scale == 1.0) return config;
  config.adam.non_matrix_learning_rate_factor *= float(scale);
  if (note)
    *note = fmt::format("out-of-core: the buffer holds {:.1f}% of the volume; grid learning rate scaled by {:.3g} "
                        "(--grid-lr-scale {})",
                        100 * s.resident_fraction(), scale, scale_text);
  return config;
}

}  // namespace vnr
