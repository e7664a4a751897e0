#pragma once
// Compact parameter storage (.vnr format 2, docs/MODEL_FORMAT.md section 1.5): the flat fp16
// parameter vector is cut into segments (one per MLP matrix, one per grid level), each quantized
// uniformly with its own step and entropy coded with zstd or, where smaller, a context-adaptive
// arithmetic coder (param_context_coder.h). Decoding yields fp16 parameters again, so
// inference on a loaded model runs at the speed of an unquantized one.
#include <cstdint>
#include <string>
#include <vector>
#include "vnr/json.h"
#include "vnr/model_config.h"
#include "vnr/nn/param_context_coder.h"

namespace vnr {

// params_encoding codecs: zstd only, or some segments context coded (docs/MODEL_FORMAT.md 1.5).
constexpr const char* kParamsZstdCodec = "quant-zstd";
constexpr const char* kParamsContextCodec = "quant-ctx";

// One run of consecutive parameters sharing a quantization step. step == 0 keeps them as raw fp16.
struct ParamSegment {
  uint64_t count = 0;
  float step = 0;
  IndexLayout layout;  // what the context coder conditions on (param_segments fills it)
};

// |q| <= kMaxQuantIndex: then fp16(q * step) rounds back to q, so quantizing a dequantized vector
// again is exact (fp16's relative error 2^-11 times 1023 steps stays under half a step).
constexpr int32_t kMaxQuantIndex = 1023;

// The segments of a config's flat parameter vector (tcnn order: MLP matrices, then grid levels);
// an encoding without a grid is one segment. Steps are 0 (raw) until the caller sets them.
std::vector<ParamSegment> param_segments(const ModelConfig& config);

// Quantize-dequantize in place with the segments' steps: afterwards `params` hold exactly what a
// model file written with these segments returns when read. A step too fine for kMaxQuantIndex
// (step < max|p| / 1023) is raised to that floor first, in `segments`. No segments: nothing to do.
void quantize_params(std::vector<uint16_t>& params, std::vector<ParamSegment>& segments);

// Encodes `params` (quantized with `segments`, values beyond the index range clamped) into the
// compressed block; `meta` receives the per-segment description that the header stores. `*codec` is
// "quant-ctx" when some segment is context coded, else "quant-zstd" (which older vnr reads too).
std::string encode_params(const std::vector<uint16_t>& params, const std::vector<ParamSegment>& segments,
                          Json& meta, std::string* codec, int zstd_level = 19);

// Decodes a block written by encode_params (either codec). Every size is checked against `meta` and `n_params`;
// damage is a vnr::Error naming `path`. Fills `segments` with the stored steps.
std::vector<uint16_t> decode_params(const std::string& path, const char* block, uint64_t block_bytes,
                                    const Json& meta, uint64_t n_params, std::vector<ParamSegment>& segments);

// Copies the layouts of param_segments(config) onto `segments` where the counts agree: zstd segments
// read from a file record none, and writing what was read must code them as before. A config that does
// not parse leaves them as they are (the model itself then fails to load, with its own error).
void restore_segment_layouts(const Json& config, std::vector<ParamSegment>& segments);

// Macro-cell ranges in 8 bits (formats 2 and 3, compact models): each min rounded down and each max rounded
// up to a multiple of 1/255, so a decoded range always contains the stored one and empty-space
// skipping stays conservative; empty cells (min > max) stay empty. zstd-coded, min and max planes.
// Only for ranges inside [0, 1] (and empty ones): macrocells_fit_u8 says whether they are.
bool macrocells_fit_u8(const std::vector<float>& ranges);
std::string encode_macrocells_u8(const std::vector<float>& ranges);
std::vector<float> decode_macrocells_u8(const std::string& path, const char* block, uint64_t bytes, uint64_t cells);

}  // namespace vnr
