#pragma once
// RGBA8 <-> JPEG through libturbojpeg: the server encodes each frame image once (quality 85, 4:2:0)
// and sends the same bytes to every client.
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace vnr::view {

constexpr int kJpegQuality = 85;

// One compressor (libturbojpeg handles are not shared between threads: one per thread).
class JpegEncoder {
public:
  JpegEncoder();
  ~JpegEncoder();
  JpegEncoder(const JpegEncoder&) = delete;
  JpegEncoder& operator=(const JpegEncoder&) = delete;
  // Appends the JPEG of width x height RGBA8 pixels (row 0 at the top; alpha dropped) to out.
  void encode(const uint8_t* rgba, int width, int height, std::string* out);

private:
  void* handle_;
};

struct DecodedJpeg {
  int width = 0, height = 0;
  std::vector<uint8_t> rgba;  // alpha 255
};
// vnr::Error on bytes that are not a JPEG.
DecodedJpeg decode_jpeg(std::string_view bytes);

}  // namespace vnr::view
