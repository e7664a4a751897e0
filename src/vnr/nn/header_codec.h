#pragma once
#include <string>
#include <string_view>

namespace vnr {

// Format-3 .vnr headers (docs/MODEL_FORMAT.md 1.6) are one zstd frame coded against a fixed raw-content
// dictionary of typical headers: a 2.5 kB header becomes about 0.4 kB, which a 20 kB model at 128x
// spends on its residuals instead.
extern const std::string_view kVnrHeaderDictionary;

// The header JSON text as one zstd frame (content size recorded) against kVnrHeaderDictionary.
std::string compress_vnr_header(std::string_view json);
// The JSON text of a frame written by compress_vnr_header. A frame that does not decode, declares no
// size or more than max_bytes is one "'path' is corrupted (…)" error.
std::string decompress_vnr_header(const std::string& path, std::string_view frame, size_t max_bytes);

}  // namespace vnr
