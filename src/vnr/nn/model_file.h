#pragma once
#include <cstdint>
#include <string>
#include <vector>
#include "vnr/json.h"
#include "vnr/math.h"
#include "vnr/dtype.h"
#include "vnr/nn/param_codec.h"

namespace vnr {

// Everything a trained model file holds, independent of the in-memory network classes.
struct ModelFile {
  Json config;                    // full tcnn-style config: {"encoding","network","loss","optimizer"}
  Int3 dims;                      // the volume the model represents
  DType source_dtype = DType::Float32;
  double lo = 0, hi = 1;          // value range in original units (decode maps u -> lo + u (hi - lo))
  std::vector<uint16_t> params;   // IEEE fp16 bits, tcnn flat order (MLP first, then the grid)
  // Optional macro-cells: value range [min, max] (normalised units) per cell, x fastest.
  Int3 macrocell_dims;            // {0,0,0} when absent
  std::vector<float> macrocell_ranges;  // 2 * macrocell_dims.count() floats: min0, max0, min1, ...
  Json training;                  // optional training summary (steps, seconds, psnr...); may be null
  // Optional error-bound residuals (docs/MODEL_FORMAT.md): an opaque block owned by the train layer,
  // described by residuals_meta; both empty when absent. A file with them is format version 3 (or 2).
  Json residuals_meta;
  std::vector<uint8_t> residuals_bytes;
  // Optional compact storage (param_codec.h): when non-empty, write_vnr stores `params` quantized
  // with these per-segment steps and zstd-coded (format version 3, or 2); read_vnr fills them back and
  // dequantizes into `params`. Call quantize_params first so that `params` equal what a read returns.
  std::vector<ParamSegment> param_segments;
  // Store the macro-cell ranges in 8 bits, widened outwards (param_codec.h; format version 3, or 2). Set by
  // read_vnr when the file stores them so. Ranges outside [0, 1] are then stored as float32 anyway.
  bool compact_macrocells = false;
};

// Native .vnr format (docs/MODEL_FORMAT.md): magic "VNRMODEL", format version, a JSON header (config,
// dims, dtype, range, macro-cell dims, param count, training summary), then the fp16 parameter
// block (or, formats 2 and 3, the compressed one), the macro-cell block and (2, 3) the residual block,
// then a CRC-32 of everything before it. Written atomically: format 1 for a model that needs nothing
// more, else format 3 (format 2 plus a zstd-coded header); format 2 is read as before.
// Loading a truncated, corrupted or newer-version file is a clear error.
void write_vnr(const std::string& path, const ModelFile& m);
ModelFile read_vnr(const std::string& path);
// The exact size write_vnr would give the file (encodes it in memory; used by rate control).
uint64_t vnr_file_bytes(const ModelFile& m);

// instantvnr's "params.json" (BSON, docs/semantics.md A.5 and docs/MODEL_FORMAT.md section 2).
// The BSON file does not carry dtype/range or the optimizer: read_instantvnr leaves source_dtype
// Float32, lo = 0, hi = 1 and takes the paper's default optimizer. A file without "volume" (legacy)
// leaves dims {0,0,0}; one without "macrocell" leaves macro-cells absent. Macro-cell ranges
// are stored as float (min - 1, max + 1), so a BSON round trip keeps them to about 1.2e-7 absolute.
void write_instantvnr(const std::string& path, const ModelFile& m);
ModelFile read_instantvnr(const std::string& path);

// Reads either format, chosen by content (the .vnr magic), not by extension.
ModelFile read_model(const std::string& path);

}  // namespace vnr
