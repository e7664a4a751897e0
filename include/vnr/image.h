#pragma once
// vnr's images: framebuffers and image files (the renderer's, the viewer's and a front end's alike). Row 0 is the top row. Pixel values are the renderer's colours,
// written to 8-bit PNG as display (sRGB-encoded) values without further transfer, the way
// instantvnr and VTK show them; PFM keeps the exact floats.
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>
#include "vnr/math.h"

namespace vnr {

struct Image {
  int width = 0, height = 0;
  std::vector<Vec4f> pixels;  // width * height, row-major, row 0 = top
  Image() = default;
  Image(int w, int h) : width(w), height(h), pixels(size_t(w) * h) {}
  Vec4f& at(int x, int y) { return pixels[size_t(y) * width + x]; }
  const Vec4f& at(int x, int y) const { return pixels[size_t(y) * width + x]; }
};

// By extension: .png (8-bit RGB, each channel round(255 * clamp(c, 0, 1)), sRGB chunk) or .pfm
// (binary32 RGB, little-endian, exact). Written atomically. Any other extension is an error.
void write_image(const std::string& path, const Image& img);
// The bytes of the .png file write_image writes for img (same 8-bit conversion and sRGB chunk).
std::vector<uint8_t> encode_png(const Image& img);
// One colour channel in 8 bits as PNG output writes it: round(255 * clamp(c, 0, 1)), halves up; NaN gives
// 0. The sum is at least 0.5, so truncation is the floor: one vector instruction, where std::floor is a
// call per channel on x86-64's baseline (docs/benchmarks.md, "The viewer's frame on the GPU").
VNR_HD inline uint8_t channel_to_u8(float c) {
  return uint8_t(int(255.0f * (c > 0 ? (c < 1 ? c : 1.0f) : 0.0f) + 0.5f));
}
// A pixel as to_rgba8 stores it: one little-endian word, R in the low byte, alpha 255 (also on the GPU).
VNR_HD inline uint32_t rgba8_word(Vec4f p) {
  return uint32_t(channel_to_u8(p.x)) | uint32_t(channel_to_u8(p.y)) << 8 | uint32_t(channel_to_u8(p.z)) << 16 |
         0xff000000u;
}
// 8-bit RGBA, row 0 at the top: each colour channel exactly as PNG output writes it (round(255 *
// clamp(c, 0, 1))), alpha 255 (the image is already composited over the background).
std::vector<uint8_t> to_rgba8(const Image& img);
// The image of w x h RGBA8 bytes: channels k / 255 (to_rgba8 gives back the bytes), alpha 1.
Image image_of_rgba8(const uint8_t* rgba, int w, int h);
// Reads .png (8-bit or 16-bit, gray/RGB/RGBA, palette) or .pfm; alpha = 1.
Image read_image(const std::string& path);

// docs/semantics.md B.4: PSNR (peak 1) and mean 2-D SSIM (7x7 uniform window, K1 = 0.01, K2 = 0.03, data
// range 1, sample covariance) over the RGB channels clamped to [0,1]; alpha ignored. Sizes must match.
// mse is over all pixels and the three channels; psnr = 999 when mse == 0 (as for volumes: JSON has
// no infinity). SSIM is averaged over the 7x7 windows fully inside the image and over R, G, B
// (vnr/metrics.h ssim3d with one slice); an image narrower or shorter than 7 uses its whole width or
// height as the window.
struct ImageMetrics {
  double psnr = 0, ssim = 0, mse = 0;
};
ImageMetrics compare_images(const Image& img, const Image& reference);

}  // namespace vnr
