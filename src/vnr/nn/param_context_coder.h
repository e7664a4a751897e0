#pragma once
// Context-adaptive arithmetic coding of one parameter segment's quantization indices (format 2's
// `quant-ctx` segments, docs/MODEL_FORMAT.md 1.5): param_codec.cpp keeps it where it codes smaller
// than zstd.
#include <cstddef>
#include <cstdint>
#include <vector>

namespace vnr {

// How a segment's indices are laid out, which is what the contexts look at: `entry` indices per
// table entry (a grid level's features; 1 for MLP matrices), and for a dense grid level its
// vertices per axis (`res`, entry x + y·res + z·res², 0 otherwise). Decoding needs the same layout.
struct IndexLayout {
  uint32_t entry = 1, res = 0;
};

std::vector<uint8_t> encode_param_indices(const int32_t* q, uint64_t n, IndexLayout layout);

// The inverse into q[0, n); false when the stream is damaged or truncated (a code too long, or reading
// past its end), in which case q holds garbage.
bool decode_param_indices(const uint8_t* data, size_t bytes, uint64_t n, IndexLayout layout, int32_t* q);

}  // namespace vnr
