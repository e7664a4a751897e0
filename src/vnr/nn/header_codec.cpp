#include "vnr/nn/header_codec.h"
#include <zstd.h>
#include <memory>
#include "vnr/error.h"

namespace vnr {
namespace {

// Level 19: headers are a few kB, so the strongest level costs about a millisecond per write.
constexpr int kHeaderZstdLevel = 19;

}  // namespace

std::string compress_vnr_header(std::string_view json) {
  std::unique_ptr<ZSTD_CCtx, decltype(&ZSTD_freeCCtx)> ctx(ZSTD_createCCtx(), ZSTD_freeCCtx);
  if (!ctx) fail("cannot allocate a zstd context for the model header");
  std::string frame(ZSTD_compressBound(json.size()), '\0');
  const size_t got = ZSTD_compress_usingDict(ctx.get(), frame.data(), frame.size(), json.data(), json.size(),
                                             kVnrHeaderDictionary.data(), kVnrHeaderDictionary.size(),
                                             kHeaderZstdLevel);
  if (ZSTD_isError(got)) fail("cannot compress the model header: {}", ZSTD_getErrorName(got));
  frame.resize(got);
  return frame;
}

std::string decompress_vnr_header(const std::string& path, std::string_view frame, size_t max_bytes) {
  const unsigned long long n = ZSTD_getFrameContentSize(frame.data(), frame.size());
  if (n == ZSTD_CONTENTSIZE_ERROR || n == ZSTD_CONTENTSIZE_UNKNOWN)
    fail("'{}' is corrupted (the compressed header is not a zstd frame of known size)", path);
  if (n > max_bytes) fail("'{}' is corrupted (the header claims {} bytes, more than {})", path, n, max_bytes);
  std::unique_ptr<ZSTD_DCtx, decltype(&ZSTD_freeDCtx)> ctx(ZSTD_createDCtx(), ZSTD_freeDCtx);
  if (!ctx) fail("cannot allocate a zstd context to read '{}'", path);
  std::string json(size_t(n), '\0');
  const size_t got = ZSTD_decompress_usingDict(ctx.get(), json.data(), json.size(), frame.data(), frame.size(),
                                               kVnrHeaderDictionary.data(), kVnrHeaderDictionary.size());
  if (ZSTD_isError(got) || got != n)
    fail("'{}' is corrupted (the compressed header does not decode: {})", path,
         ZSTD_isError(got) ? ZSTD_getErrorName(got) : "short frame");
  return json;
}

}  // namespace vnr
