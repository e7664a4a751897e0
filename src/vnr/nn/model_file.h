#pragma once
#include <cstdint>
#include <string>
#include <vector>
#include "vnr/core/json.h"
#include "vnr/core/math.h"
#include "vnr/core/dtype.h"

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
  // described by residuals_meta; both empty when absent. A file with them is format version 2.
  Json residuals_meta;
  std::vector<uint8_t> residuals_bytes;
};

// Native .vnr format (docs/MODEL_FORMAT.md): magic "VNRMODEL", format version, a JSON header (config,
// dims, dtype, range, macro-cell dims, param count, training summary), then the fp16 parameter
// block and the macro-cell block, then a CRC-32 of everything before it. Written atomically.
// Loading a truncated, corrupted or newer-version file is a clear error.
void write_vnr(const std::string& path, const ModelFile& m);
ModelFile read_vnr(const std::string& path);

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
