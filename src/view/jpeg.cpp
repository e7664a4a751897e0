// libturbojpeg glue.
#include "view/jpeg.h"
#include <turbojpeg.h>
#include "vnr/error.h"

namespace vnr::view {

JpegEncoder::JpegEncoder() : handle_(tjInitCompress()) {
  if (!handle_) fail("cannot create a JPEG compressor: {}", tjGetErrorStr2(nullptr));
}

JpegEncoder::~JpegEncoder() { tjDestroy(handle_); }

void JpegEncoder::encode(const uint8_t* rgba, int width, int height, std::string* out) {
  if (width <= 0 || height <= 0) fail("cannot encode an empty {}x{} image as JPEG", width, height);
  unsigned char* buf = nullptr;  // allocated by libturbojpeg
  unsigned long size = 0;
  // 4:2:0 chroma and the fast DCT: a frame is shown once and replaced; speed matters more than the
  // last fraction of a dB.
  const int rc = tjCompress2(handle_, rgba, width, 0, height, TJPF_RGBA, &buf, &size, TJSAMP_420, kJpegQuality,
                             TJFLAG_FASTDCT);
  if (rc != 0) {
    const std::string msg = tjGetErrorStr2(handle_);
    tjFree(buf);
    fail("JPEG encoding failed: {}", msg);
  }
  out->append(reinterpret_cast<const char*>(buf), size);
  tjFree(buf);
}

DecodedJpeg decode_jpeg(std::string_view bytes) {
  tjhandle h = tjInitDecompress();
  if (!h) fail("cannot create a JPEG decompressor");
  auto* src = reinterpret_cast<const unsigned char*>(bytes.data());
  int w = 0, hgt = 0, subsamp = 0, colorspace = 0;
  DecodedJpeg d;
  if (tjDecompressHeader3(h, src, bytes.size(), &w, &hgt, &subsamp, &colorspace) != 0 || w <= 0 || hgt <= 0) {
    const std::string msg = tjGetErrorStr2(h);
    tjDestroy(h);
    fail("not a JPEG image: {}", msg);
  }
  d.width = w;
  d.height = hgt;
  d.rgba.resize(size_t(w) * size_t(hgt) * 4);
  if (tjDecompress2(h, src, bytes.size(), d.rgba.data(), w, 0, hgt, TJPF_RGBA, 0) != 0) {
    const std::string msg = tjGetErrorStr2(h);
    tjDestroy(h);
    fail("corrupt JPEG image: {}", msg);
  }
  tjDestroy(h);
  return d;
}

}  // namespace vnr::view
