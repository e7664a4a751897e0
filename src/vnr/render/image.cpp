// Image files (PNG through libpng, PFM by hand) and image metrics.
#include "vnr/render/image.h"
#include <png.h>
#include <algorithm>
#include <bit>
#include <csetjmp>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include "vnr/core/parallel.h"
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/metrics.h"

namespace vnr {

namespace {

// NaN -> 0, then clamp to [0,1].
inline float clamp01(float v) { return v > 0 ? (v < 1 ? v : 1.0f) : 0.0f; }

void check_image(const Image& img, const std::string& what) {
  if (img.width <= 0 || img.height <= 0) fail("{}: image size {}x{} is empty", what, img.width, img.height);
  if (img.pixels.size() != size_t(img.width) * size_t(img.height))
    fail("{}: image has {} pixels, expected {}x{}", what, img.pixels.size(), img.width, img.height);
}

// ---- libpng glue ---------------------------------------------------------------------------------
// libpng reports errors by longjmp. The functions that call setjmp keep only trivially destructible
// locals, so no C++ destructor is ever skipped; buffers live in the caller's frame.

struct PngErr {
  char msg[256];
  std::jmp_buf jb;
};

void png_error_fn(png_structp png, png_const_charp msg) {
  auto* e = static_cast<PngErr*>(png_get_error_ptr(png));
  std::snprintf(e->msg, sizeof e->msg, "%s", msg ? msg : "unknown libpng error");
  std::longjmp(e->jb, 1);
}
void png_warning_fn(png_structp, png_const_charp) {}

void png_write_cb(png_structp png, png_bytep data, png_size_t len) {
  static_cast<std::string*>(png_get_io_ptr(png))->append(reinterpret_cast<const char*>(data), len);
}
void png_flush_cb(png_structp) {}

bool encode_png(std::string* out, const uint8_t* rgb, int w, int h, PngErr* e) {
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, e, png_error_fn, png_warning_fn);
  if (!png) {
    std::snprintf(e->msg, sizeof e->msg, "cannot create the PNG writer");
    return false;
  }
  png_infop info = png_create_info_struct(png);
  if (!info) {
    png_destroy_write_struct(&png, nullptr);
    std::snprintf(e->msg, sizeof e->msg, "cannot create the PNG writer");
    return false;
  }
  if (setjmp(e->jb)) {
    png_destroy_write_struct(&png, &info);
    return false;
  }
  png_set_write_fn(png, out, png_write_cb, png_flush_cb);
  png_set_IHDR(png, info, png_uint_32(w), png_uint_32(h), 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_set_sRGB(png, info, PNG_sRGB_INTENT_PERCEPTUAL);
  png_write_info(png, info);
  for (int y = 0; y < h; ++y) png_write_row(png, const_cast<png_bytep>(rgb + size_t(y) * size_t(w) * 3));
  png_write_end(png, info);
  png_destroy_write_struct(&png, &info);
  return true;
}

struct PngSource {
  const unsigned char* data;
  size_t size, pos;
};

void png_read_cb(png_structp png, png_bytep out, png_size_t len) {
  auto* s = static_cast<PngSource*>(png_get_io_ptr(png));
  if (len > s->size - s->pos) png_error(png, "file is truncated");
  std::memcpy(out, s->data + s->pos, len);
  s->pos += len;
}

struct PngDecoded {
  int width = 0, height = 0, channels = 0, bit_depth = 0;
  size_t rowbytes = 0;
};

// Decodes into `pixels` (rows top to bottom): 8- or 16-bit (big-endian) samples, 3 or 4 channels.
bool decode_png(PngSource* src, std::vector<unsigned char>* pixels, std::vector<png_bytep>* rows,
                PngDecoded* d, PngErr* e) {
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, e, png_error_fn, png_warning_fn);
  if (!png) {
    std::snprintf(e->msg, sizeof e->msg, "cannot create the PNG reader");
    return false;
  }
  png_infop info = png_create_info_struct(png);
  if (!info) {
    png_destroy_read_struct(&png, nullptr, nullptr);
    std::snprintf(e->msg, sizeof e->msg, "cannot create the PNG reader");
    return false;
  }
  if (setjmp(e->jb)) {
    png_destroy_read_struct(&png, &info, nullptr);
    return false;
  }
  png_set_read_fn(png, src, png_read_cb);
  png_read_info(png, info);
  const int color_type = png_get_color_type(png, info);
  const int depth = png_get_bit_depth(png, info);
  if (color_type == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
  if (color_type == PNG_COLOR_TYPE_GRAY && depth < 8) png_set_expand_gray_1_2_4_to_8(png);
  if (color_type == PNG_COLOR_TYPE_GRAY || color_type == PNG_COLOR_TYPE_GRAY_ALPHA) png_set_gray_to_rgb(png);
  png_set_interlace_handling(png);
  png_read_update_info(png, info);
  if (uint64_t(png_get_image_width(png, info)) * png_get_image_height(png, info) > (uint64_t(1) << 28))
    png_error(png, "image is too large (more than 2^28 pixels)");
  d->width = int(png_get_image_width(png, info));
  d->height = int(png_get_image_height(png, info));
  d->channels = png_get_channels(png, info);
  d->bit_depth = png_get_bit_depth(png, info);
  d->rowbytes = png_get_rowbytes(png, info);
  if ((d->channels != 3 && d->channels != 4) || (d->bit_depth != 8 && d->bit_depth != 16))
    png_error(png, "unsupported pixel layout after conversion");
  pixels->resize(d->rowbytes * size_t(d->height));
  rows->resize(size_t(d->height));
  for (int y = 0; y < d->height; ++y) (*rows)[size_t(y)] = pixels->data() + d->rowbytes * size_t(y);
  png_read_image(png, rows->data());
  png_destroy_read_struct(&png, &info, nullptr);
  return true;
}

// The PNG bytes of img (8-bit RGB, round(255 * clamp(c, 0, 1)), sRGB chunk); `what` names it in errors.
std::string png_bytes(const Image& img, const std::string& what) {
  std::vector<uint8_t> rgb(size_t(img.width) * size_t(img.height) * 3);
  for (size_t i = 0; i < img.pixels.size(); ++i) {
    const Vec4f& p = img.pixels[i];
    rgb[3 * i + 0] = channel_to_u8(p.x);
    rgb[3 * i + 1] = channel_to_u8(p.y);
    rgb[3 * i + 2] = channel_to_u8(p.z);
  }
  std::string out;
  PngErr e{};
  if (!encode_png(&out, rgb.data(), img.width, img.height, &e)) fail("cannot write {}: libpng: {}", what, e.msg);
  return out;
}

void write_png(const std::string& path, const Image& img) { write_file_atomic(path, png_bytes(img, "'" + path + "'")); }

Image read_png(const std::string& path) {
  const std::string data = read_file(path);
  if (data.size() < 8 || png_sig_cmp(reinterpret_cast<png_const_bytep>(data.data()), 0, 8) != 0)
    fail("'{}' is not a PNG file (bad signature)", path);
  PngSource src{reinterpret_cast<const unsigned char*>(data.data()), data.size(), 0};
  std::vector<unsigned char> pixels;
  std::vector<png_bytep> rows;
  PngDecoded d;
  PngErr e{};
  if (!decode_png(&src, &pixels, &rows, &d, &e)) fail("'{}': corrupt PNG file ({})", path, e.msg);
  Image img(d.width, d.height);
  const int bps = d.bit_depth / 8;
  const float maxv = d.bit_depth == 16 ? 65535.0f : 255.0f;  // divide: k/255 reads back exactly
  for (int y = 0; y < d.height; ++y) {
    const unsigned char* row = pixels.data() + d.rowbytes * size_t(y);
    for (int x = 0; x < d.width; ++x) {
      float c[3];
      for (int k = 0; k < 3; ++k) {
        const unsigned char* s = row + (size_t(x) * d.channels + k) * bps;
        c[k] = float(bps == 2 ? (unsigned(s[0]) << 8 | s[1]) : s[0]) / maxv;
      }
      img.at(x, y) = Vec4f{c[0], c[1], c[2], 1.0f};
    }
  }
  return img;
}

// ---- PFM -----------------------------------------------------------------------------------------

uint32_t bswap32(uint32_t u) { return __builtin_bswap32(u); }

void write_pfm(const std::string& path, const Image& img) {
  std::string out = fmt::format("PF\n{} {}\n-1.0\n", img.width, img.height);
  const size_t header = out.size();
  out.resize(header + size_t(img.width) * size_t(img.height) * 12);
  char* p = out.data() + header;
  for (int y = img.height - 1; y >= 0; --y)  // PFM rows run bottom to top
    for (int x = 0; x < img.width; ++x) {
      const Vec4f& c = img.at(x, y);
      for (float v : {c.x, c.y, c.z}) {
        uint32_t u;
        std::memcpy(&u, &v, 4);
        if constexpr (std::endian::native == std::endian::big) u = bswap32(u);
        std::memcpy(p, &u, 4);
        p += 4;
      }
    }
  write_file_atomic(path, out);
}

Image read_pfm(const std::string& path) {
  const std::string data = read_file(path);
  size_t pos = 0;
  auto is_space = [](char c) { return c == ' ' || c == '\n' || c == '\r' || c == '\t'; };
  auto token = [&](const char* what) {
    while (pos < data.size() && is_space(data[pos])) ++pos;
    const size_t b = pos;
    while (pos < data.size() && !is_space(data[pos]) && pos - b < 64) ++pos;
    if (b == pos) fail("'{}': corrupt PFM header (missing {})", path, what);
    return data.substr(b, pos - b);
  };
  if (data.size() < 2 || data[0] != 'P' || (data[1] != 'F' && data[1] != 'f'))
    fail("'{}' is not a PFM file (expected \"PF\" or \"Pf\")", path);
  const std::string magic = token("magic");
  if (magic != "PF" && magic != "Pf") fail("'{}' is not a PFM file (expected \"PF\" or \"Pf\")", path);
  const int channels = magic == "PF" ? 3 : 1;
  auto integer = [&](const char* what) {
    const std::string t = token(what);
    char* end = nullptr;
    const long v = std::strtol(t.c_str(), &end, 10);
    if (*end != '\0' || v <= 0 || v > (1 << 20)) fail("'{}': corrupt PFM header (bad {} \"{}\")", path, what, t);
    return int(v);
  };
  const int w = integer("width"), h = integer("height");
  const std::string st = token("scale");
  char* end = nullptr;
  const double scale = std::strtod(st.c_str(), &end);
  if (*end != '\0' || !std::isfinite(scale) || scale == 0)
    fail("'{}': corrupt PFM header (bad scale \"{}\")", path, st);
  if (pos >= data.size() || !is_space(data[pos])) fail("'{}': corrupt PFM header", path);
  ++pos;  // exactly one whitespace character before the raster
  const bool little = scale < 0;
  const size_t need = size_t(w) * size_t(h) * size_t(channels) * 4;
  if (data.size() - pos < need)
    fail("'{}': PFM data is truncated ({} bytes, expected {})", path, data.size() - pos, need);
  const bool swap = little != (std::endian::native == std::endian::little);
  const char* p = data.data() + pos;
  Image img(w, h);
  for (int y = h - 1; y >= 0; --y)
    for (int x = 0; x < w; ++x) {
      float c[3];
      for (int k = 0; k < channels; ++k) {
        uint32_t u;
        std::memcpy(&u, p, 4);
        p += 4;
        if (swap) u = bswap32(u);
        std::memcpy(&c[k], &u, 4);
      }
      if (channels == 1) c[1] = c[2] = c[0];
      img.at(x, y) = Vec4f{c[0], c[1], c[2], 1.0f};
    }
  return img;
}

}  // namespace

std::vector<uint8_t> encode_png(const Image& img) {
  check_image(img, "a PNG image in memory");
  const std::string bytes = png_bytes(img, "a PNG image in memory");
  return std::vector<uint8_t>(bytes.begin(), bytes.end());
}

void write_image(const std::string& path, const Image& img) {
  check_image(img, path);
  const std::string ext = extension_of(path);
  if (ext == ".png") return write_png(path, img);
  if (ext == ".pfm") return write_pfm(path, img);
  fail("cannot write '{}': unknown image extension '{}' (use .png or .pfm)", path, ext);
}

Image read_image(const std::string& path) {
  const std::string ext = extension_of(path);
  if (ext == ".png") return read_png(path);
  if (ext == ".pfm") return read_pfm(path);
  fail("cannot read '{}': unknown image extension '{}' (use .png or .pfm)", path, ext);
}

ImageMetrics compare_images(const Image& img, const Image& reference) {
  check_image(img, "image");
  check_image(reference, "reference image");
  if (img.width != reference.width || img.height != reference.height)
    fail("image size mismatch: {}x{} vs reference {}x{}", img.width, img.height, reference.width, reference.height);
  const size_t n = img.pixels.size();
  std::vector<float> a(n), b(n);
  ImageMetrics m;
  double ssim_sum = 0, se = 0;
  for (int k = 0; k < 3; ++k) {
    for (size_t i = 0; i < n; ++i) {
      const Vec4f &p = img.pixels[i], &q = reference.pixels[i];
      a[i] = clamp01(k == 0 ? p.x : (k == 1 ? p.y : p.z));
      b[i] = clamp01(k == 0 ? q.x : (k == 1 ? q.y : q.z));
      const double d = double(a[i]) - double(b[i]);
      se += d * d;
    }
    // 2-D SSIM = the 3-D one with a single slice (window 7x7x1); axes shorter than 7 use the whole axis.
    ssim_sum += ssim3d(b.data(), a.data(), Int3{img.width, img.height, 1});
  }
  m.mse = se / double(3 * n);
  m.psnr = m.mse > 0 ? 10.0 * std::log10(1.0 / m.mse) : 999.0;
  m.ssim = ssim_sum / 3.0;
  return m;
}

Image image_of_rgba8(const uint8_t* rgba, int w, int h) {
  Image img(w, h);
  for (size_t i = 0; i < img.pixels.size(); ++i) {
    const uint8_t* p = rgba + 4 * i;
    img.pixels[i] = Vec4f{float(p[0]) / 255.0f, float(p[1]) / 255.0f, float(p[2]) / 255.0f, 1.0f};
  }
  return img;
}

std::vector<uint8_t> to_rgba8(const Image& img) {
  std::vector<uint8_t> out(img.pixels.size() * 4);
  // A pixel's four bytes as one little-endian word, stored at once; runs of pixels on every thread (a
  // viewer's frame each time: on a GPU machine the cores are otherwise idle then).
  static_assert(std::endian::native == std::endian::little);
  parallel_for_range(int64_t(img.pixels.size()), int64_t(1) << 15, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) {
      const uint32_t rgba = rgba8_word(img.pixels[size_t(i)]);
      std::memcpy(out.data() + 4 * i, &rgba, 4);
    }
  });
  return out;
}

}  // namespace vnr
