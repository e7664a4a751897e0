// Images (PNG and PFM reading and writing) and image metrics (MSE, PSNR, SSIM).
#include <gtest/gtest.h>
#include <png.h>
#include <unistd.h>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <numbers>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/json.h"
#include "vnr/core/rng.h"
#include "vnr/render/camera.h"
#include "vnr/render/image.h"
#include "vnr/scene.h"
#include "vnr/render/transfer_function.h"
#include "test_support.h"

using namespace vnr;
using namespace vnr::test;

namespace {

Image random_image(int w, int h, uint64_t seed, float lo = 0, float hi = 1) {
  Pcg32 rng(seed);
  Image img(w, h);
  for (auto& p : img.pixels)
    p = Vec4f{lo + (hi - lo) * rng.next_float(), lo + (hi - lo) * rng.next_float(), lo + (hi - lo) * rng.next_float(), 1};
  return img;
}

}  // namespace

// ---- images -------------------------------------------------------------------------------------

TEST(Image, PngRoundTripWithin8Bits) {
  TmpDir dir;
  Image img = random_image(37, 23, 5, -0.2f, 1.2f);  // out-of-range values clamp
  img.at(0, 0) = Vec4f{NAN, 1.0f / 255, 254.0f / 255, 0.5f};
  const std::string path = dir / "a.png";
  write_image(path, img);
  Image back = read_image(path);
  ASSERT_EQ(back.width, 37);
  ASSERT_EQ(back.height, 23);
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const Vec4f a = img.at(x, y), b = back.at(x, y);
      const float ca[3] = {a.x, a.y, a.z}, cb[3] = {b.x, b.y, b.z};
      for (int k = 0; k < 3; ++k) {
        const float want = std::isnan(ca[k]) ? 0.0f : std::clamp(ca[k], 0.0f, 1.0f);
        ASSERT_NEAR(cb[k], want, 0.5f / 255 + 1e-6f) << x << "," << y;
      }
      EXPECT_EQ(b.w, 1.0f);
    }
  EXPECT_EQ(back.at(0, 0).y, 1.0f / 255);
  EXPECT_EQ(back.at(0, 0).z, 254.0f / 255);
  // 8-bit RGB with an sRGB chunk, row 0 at the top.
  const std::string bytes = read_file(path);
  EXPECT_NE(bytes.find("sRGB"), std::string::npos);
  EXPECT_EQ(uint8_t(bytes[24]), 8);  // IHDR bit depth
  EXPECT_EQ(uint8_t(bytes[25]), 2);  // IHDR colour type RGB
  EXPECT_FALSE(file_exists(path + ".tmp-" + std::to_string(::getpid())));
}

// channel_to_u8 against round-half-up of float(255 c) written with std::floor in double precision (exact),
// over every 4096th float bit pattern of both signs, the specials, each 8-bit level and the ties between
// levels; to_rgba8 packs the same bytes in RGBA order, and image_of_rgba8 reads them back.
TEST(Image, ChannelTo8BitsRoundsHalvesUpAndClamps) {
  auto reference = [](float c) -> int {
    if (!(c > 0)) return 0;
    if (c >= 1) return 255;
    return int(std::floor(double(255.0f * c) + 0.5));
  };
  for (uint64_t bits = 0; bits <= 0xffffffffu; bits += 4096) {
    const uint32_t b = uint32_t(bits);
    float c;
    std::memcpy(&c, &b, 4);
    ASSERT_EQ(int(channel_to_u8(c)), reference(c)) << c;
  }
  for (float c : {0.0f, -0.0f, 1.0f, NAN, -NAN, INFINITY, -INFINITY, std::numeric_limits<float>::denorm_min()})
    EXPECT_EQ(int(channel_to_u8(c)), reference(c)) << c;
  for (int k = 0; k < 255; ++k) {
    const float tie = (float(k) + 0.5f) / 255.0f;  // rounds to k or k + 1 as 255 * tie lands
    EXPECT_EQ(int(channel_to_u8(tie)), reference(tie)) << k;
    EXPECT_EQ(int(channel_to_u8(float(k) / 255.0f)), k);
  }
  Image img(2, 1);
  img.at(0, 0) = Vec4f{1.0f, 0.5f, 0.0f, 0.25f};
  img.at(1, 0) = Vec4f{NAN, 2.0f, 1.0f / 255, 0.0f};
  EXPECT_EQ(to_rgba8(img), (std::vector<uint8_t>{255, 128, 0, 255, 0, 255, 1, 255}));
  std::vector<uint8_t> every(4 * 256);  // the way back: each level k as k / 255, which gives k again
  for (int k = 0; k < 256; ++k) {
    for (int c = 0; c < 3; ++c) every[size_t(4 * k + c)] = uint8_t(k);
    every[size_t(4 * k + 3)] = 255;
  }
  const Image back = image_of_rgba8(every.data(), 16, 16);
  EXPECT_EQ(back.at(3, 2).x, 35.0f / 255.0f);
  EXPECT_EQ(to_rgba8(back), every);
}

TEST(Image, PngReadsOtherPixelFormats) {
  TmpDir dir;
  // 16-bit grey, written with libpng's simplified API.
  {
    const int w = 5, h = 2;
    std::vector<uint16_t> px(w * h);
    for (int i = 0; i < w * h; ++i) px[i] = uint16_t(i * 6553 + 1);
    png_image im{};
    im.version = PNG_IMAGE_VERSION;
    im.width = w;
    im.height = h;
    im.format = PNG_FORMAT_LINEAR_Y;
    ASSERT_TRUE(png_image_write_to_file(&im, (dir / "g16.png").c_str(), 0, px.data(), 0, nullptr));
    Image img = read_image(dir / "g16.png");
    ASSERT_EQ(img.width, w);
    ASSERT_EQ(img.height, h);
    for (int i = 0; i < w * h; ++i) {
      EXPECT_FLOAT_EQ(img.pixels[i].x, px[i] / 65535.0f) << i;
      EXPECT_FLOAT_EQ(img.pixels[i].z, px[i] / 65535.0f) << i;
    }
  }
  // 8-bit RGBA: alpha ignored.
  {
    const uint8_t px[8] = {10, 20, 30, 0, 200, 100, 50, 128};
    png_image im{};
    im.version = PNG_IMAGE_VERSION;
    im.width = 2;
    im.height = 1;
    im.format = PNG_FORMAT_RGBA;
    ASSERT_TRUE(png_image_write_to_file(&im, (dir / "rgba.png").c_str(), 0, px, 0, nullptr));
    Image img = read_image(dir / "rgba.png");
    EXPECT_FLOAT_EQ(img.at(1, 0).x, 200.0f / 255);
    EXPECT_FLOAT_EQ(img.at(0, 0).z, 30.0f / 255);
    EXPECT_EQ(img.at(0, 0).w, 1.0f);
  }
  // Palette.
  {
    const uint8_t cmap[6] = {255, 0, 0, 0, 0, 255};
    const uint8_t idx[4] = {0, 1, 1, 0};
    png_image im{};
    im.version = PNG_IMAGE_VERSION;
    im.width = 2;
    im.height = 2;
    im.format = PNG_FORMAT_RGB_COLORMAP;
    im.colormap_entries = 2;
    ASSERT_TRUE(png_image_write_to_file(&im, (dir / "pal.png").c_str(), 0, idx, 0, cmap));
    Image img = read_image(dir / "pal.png");
    EXPECT_EQ(img.at(0, 0).x, 1.0f);
    EXPECT_EQ(img.at(1, 0).z, 1.0f);
    EXPECT_EQ(img.at(1, 0).x, 0.0f);
    EXPECT_EQ(img.at(0, 1).z, 1.0f);
  }
}

TEST(Image, PfmRoundTripIsExact) {
  TmpDir dir;
  Image img = random_image(5, 3, 11, -2, 3);
  img.at(0, 2) = Vec4f{1e-30f, -0.0f, 12345.678f, 1};
  const std::string path = dir / "a.pfm";
  write_image(path, img);
  Image back = read_image(path);
  ASSERT_EQ(back.width, 5);
  ASSERT_EQ(back.height, 3);
  for (size_t i = 0; i < img.pixels.size(); ++i) {
    EXPECT_EQ(std::memcmp(&back.pixels[i], &img.pixels[i], 12), 0) << i;
    EXPECT_EQ(back.pixels[i].w, 1.0f);
  }
  // Layout: header, then rows bottom to top, little-endian.
  const std::string bytes = read_file(path);
  const std::string header = "PF\n5 3\n-1.0\n";
  ASSERT_EQ(bytes.substr(0, header.size()), header);
  ASSERT_EQ(bytes.size(), header.size() + 5 * 3 * 12);
  float first;
  std::memcpy(&first, bytes.data() + header.size(), 4);
  EXPECT_EQ(first, img.at(0, 2).x);  // bottom-left pixel first
}

TEST(Image, PfmReadsBigEndianAndGreyscale) {
  TmpDir dir;
  // Big-endian "Pf" 2x2 greyscale: file rows bottom to top.
  const float vals[4] = {0.25f, 0.5f, 0.75f, 1.5f};  // bottom row (0.25, 0.5), top row (0.75, 1.5)
  std::string s = "Pf\n2 2\n1.0\n";
  for (float v : vals) {
    uint32_t u;
    std::memcpy(&u, &v, 4);
    for (int b = 3; b >= 0; --b) s += char((u >> (8 * b)) & 0xff);
  }
  write_bytes(dir / "g.pfm", s);
  Image img = read_image(dir / "g.pfm");
  ASSERT_EQ(img.width, 2);
  EXPECT_EQ(img.at(0, 1).x, 0.25f);
  EXPECT_EQ(img.at(1, 1).y, 0.5f);
  EXPECT_EQ(img.at(0, 0).z, 0.75f);
  EXPECT_EQ(img.at(1, 0).x, 1.5f);
  // Truncated raster and bad headers.
  write_bytes(dir / "t.pfm", s.substr(0, s.size() - 1));
  expect_error([&] { read_image(dir / "t.pfm"); }, {"t.pfm", "truncated"});
  write_bytes(dir / "h.pfm", "PF\n2 x\n-1\n");
  expect_error([&] { read_image(dir / "h.pfm"); }, {"h.pfm", "height"});
  write_bytes(dir / "m.pfm", "P6\n2 2\n255\n");
  expect_error([&] { read_image(dir / "m.pfm"); }, {"m.pfm", "not a PFM"});
}

TEST(Image, FileErrors) {
  TmpDir dir;
  Image img(4, 4);
  expect_error([&] { write_image(dir / "a.jpg", img); }, {"a.jpg", "unknown image extension"});
  expect_error([&] { write_image(dir / "noext", img); }, {"noext", "unknown image extension"});
  expect_error([&] { read_image(dir / "a.tif"); }, {"unknown image extension"});
  expect_error([&] { read_image(dir / "missing.png"); }, {"missing.png", "cannot open"});
  expect_error([&] { write_image(dir / "e.png", Image()); }, {"empty"});
  expect_error([&] { write_image(dir / "nodir/x.png", img); }, {"cannot write"});
  write_bytes(dir / "text.png", "hello, not a png");
  expect_error([&] { read_image(dir / "text.png"); }, {"text.png", "not a PNG"});
  // A real PNG cut short.
  write_image(dir / "ok.png", random_image(16, 16, 3));
  const std::string bytes = read_file(dir / "ok.png");
  write_bytes(dir / "cut.png", bytes.substr(0, bytes.size() / 2));
  expect_error([&] { read_image(dir / "cut.png"); }, {"cut.png", "corrupt PNG"});
  // Corrupt IHDR (CRC mismatch).
  std::string bad = bytes;
  bad[17] ^= 0x55;
  write_bytes(dir / "crc.png", bad);
  expect_error([&] { read_image(dir / "crc.png"); }, {"crc.png", "corrupt PNG"});
}

// ---- metrics ------------------------------------------------------------------------------------

namespace {

// docs/semantics.md B.4 written out directly: every 7x7 window fully inside, two-pass mean, (n-1) covariance.
double ssim_brute(const Image& a, const Image& b) {
  double total = 0;
  int count = 0;
  for (int k = 0; k < 3; ++k)
    for (int y0 = 0; y0 + 7 <= a.height; ++y0)
      for (int x0 = 0; x0 + 7 <= a.width; ++x0) {
        auto ch = [&](const Image& im, int x, int y) {
          const Vec4f p = im.at(x, y);
          return double(std::clamp(k == 0 ? p.x : (k == 1 ? p.y : p.z), 0.0f, 1.0f));
        };
        double ma = 0, mb = 0;
        for (int y = y0; y < y0 + 7; ++y)
          for (int x = x0; x < x0 + 7; ++x) ma += ch(a, x, y), mb += ch(b, x, y);
        ma /= 49;
        mb /= 49;
        double va = 0, vb = 0, cov = 0;
        for (int y = y0; y < y0 + 7; ++y)
          for (int x = x0; x < x0 + 7; ++x) {
            const double da = ch(a, x, y) - ma, db = ch(b, x, y) - mb;
            va += da * da, vb += db * db, cov += da * db;
          }
        va /= 48, vb /= 48, cov /= 48;
        const double c1 = 1e-4, c2 = 9e-4;
        total += (2 * ma * mb + c1) * (2 * cov + c2) / ((ma * ma + mb * mb + c1) * (va + vb + c2));
        ++count;
      }
  return total / count;
}

}  // namespace

TEST(ImageMetrics, IdenticalAndKnownMse) {
  Image a = random_image(20, 12, 1);
  ImageMetrics same = compare_images(a, a);
  EXPECT_EQ(same.mse, 0);
  EXPECT_EQ(same.psnr, 999.0);
  EXPECT_NEAR(same.ssim, 1, 1e-9);
  // Alpha is ignored, values are clamped to [0,1] first.
  Image b = a;
  for (auto& p : b.pixels) p.w = 0.3f;
  b.at(3, 3) = Vec4f{std::max(a.at(3, 3).x, 1.0f) + 5, a.at(3, 3).y, a.at(3, 3).z, 0};
  a.at(3, 3).x = 1.0f;
  EXPECT_EQ(compare_images(b, a).mse, 0);
  // Constant 0.5 vs 0.75 (both exact in binary): mse 1/16, psnr 10 log10(16).
  Image c(9, 9), d(9, 9);
  for (auto& p : c.pixels) p = Vec4f{0.5f, 0.5f, 0.5f, 1};
  for (auto& p : d.pixels) p = Vec4f{0.75f, 0.75f, 0.75f, 1};
  ImageMetrics m = compare_images(c, d);
  EXPECT_DOUBLE_EQ(m.mse, 1.0 / 16);
  EXPECT_NEAR(m.psnr, 10 * std::log10(16.0), 1e-12);
  // Only one channel off by 0.3 in a quarter of the pixels: mse = 0.09 / 12.
  Image e(4, 4), f(4, 4);
  for (int i = 0; i < 4; ++i) f.pixels[i].y = 0.3f;
  EXPECT_NEAR(compare_images(e, f).mse, double(0.3f) * double(0.3f) / 12, 1e-12);
}

TEST(ImageMetrics, SsimHandComputed) {
  // 7x7: a single window per channel. Constant images: variances 0, SSIM = the luminance term.
  Image c(7, 7), d(7, 7);
  for (auto& p : c.pixels) p = Vec4f{0.5f, 0.5f, 0.5f, 1};
  for (auto& p : d.pixels) p = Vec4f{0.75f, 0.75f, 0.75f, 1};
  const double c1 = 1e-4;
  EXPECT_NEAR(compare_images(c, d).ssim, (2 * 0.5 * 0.75 + c1) / (0.25 + 0.5625 + c1), 1e-9);
  // A shifted copy keeps the structure term at 1; a contrast-doubled copy keeps the luminance at 1.
  Image g(7, 7), shifted(7, 7), contrast(7, 7);
  double m = 0, var = 0;
  for (int i = 0; i < 49; ++i) {
    const float v = 0.25f + 0.125f * float(i % 5) / 4;  // multiples of 1/32: exact
    g.pixels[i] = Vec4f{v, v, v, 1};
    m += v;
  }
  m /= 49;
  for (int i = 0; i < 49; ++i) {
    const float v = g.pixels[i].x;
    var += (v - m) * (v - m);
    shifted.pixels[i] = Vec4f{v + 0.25f, v + 0.25f, v + 0.25f, 1};
    const float cv = float(m + 2 * (v - m));
    contrast.pixels[i] = Vec4f{cv, cv, cv, 1};
  }
  var /= 48;
  const double c2 = 9e-4;
  EXPECT_NEAR(compare_images(shifted, g).ssim, (2 * m * (m + 0.25) + c1) / (m * m + (m + 0.25) * (m + 0.25) + c1), 1e-7);
  EXPECT_NEAR(compare_images(contrast, g).ssim, (2 * 2 * var + c2) / (var + 4 * var + c2), 1e-6);
}

TEST(ImageMetrics, SsimOfNoisyImageMatchesBruteForce) {
  Image a = random_image(19, 13, 7);
  Image b = a;
  Pcg32 rng(99);
  for (auto& p : b.pixels) {
    p.x += 0.1f * (rng.next_float() - 0.5f);
    p.y += 0.1f * (rng.next_float() - 0.5f);
    p.z += 0.1f * (rng.next_float() - 0.5f);
  }
  ImageMetrics m = compare_images(b, a);
  EXPECT_LT(m.ssim, 0.999);
  EXPECT_GT(m.ssim, 0.5);
  EXPECT_NEAR(m.ssim, ssim_brute(b, a), 1e-9);
  EXPECT_GT(m.psnr, 20);
  EXPECT_TRUE(std::isfinite(m.psnr));
}

TEST(ImageMetrics, SizeMismatchFails) {
  expect_error([] { compare_images(Image(4, 4), Image(4, 5)); }, {"size mismatch", "4x4", "4x5"});
  expect_error([] { compare_images(Image(), Image()); }, {"empty"});
}
