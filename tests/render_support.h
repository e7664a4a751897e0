// The scene that the grid image tests of both renderers share (tests/test_render.cpp: streaming vs
// in-shader on the CPU; tests/test_gpu_render.cpp: GPU vs CPU), and the PSNR of 8-bit images.
// Header-only, in vnr::test.
#pragma once

#include <gtest/gtest.h>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>
#include "test_support.h"
#include "vnr/core/value_range_grid.h"
#include "vnr/fields/fields.h"
#include "vnr/render/camera.h"
#include "vnr/render/macrocell.h"
#include "vnr/render/transfer_function.h"

namespace vnr::test {

// Marschner-Lobb on 40x36x32 voxels as a ground-truth field, the ramp transfer function, macro-cells of
// 8 voxels and an orbit camera. Not copyable: the field views the volume.
struct GridScene {
  Volume vol = synth(Int3{40, 36, 32});
  GridField field{view_of(vol)};
  TransferFunction tf = tf_preset("ramp");
  MacroCells mc{value_ranges_from_grid(view_of(vol), 8), box_of(vol)};
  Camera cam = orbit_camera(box_of(vol), 30, 20, 30);

  GridScene() { mc.update(tf); }
  GridScene(const GridScene&) = delete;
  GridScene& operator=(const GridScene&) = delete;
};

// PSNR of two 8-bit RGBA images (peak 255).
inline double rgba8_psnr(const std::vector<uint8_t>& a, const std::vector<uint8_t>& b) {
  EXPECT_EQ(a.size(), b.size());
  double se = 0;
  for (size_t i = 0; i < a.size() && i < b.size(); ++i) se += (double(a[i]) - b[i]) * (double(a[i]) - b[i]);
  const double mse = se / double(std::max<size_t>(a.size(), 1));
  return mse == 0 ? 200.0 : 10 * std::log10(255.0 * 255.0 / mse);
}

}  // namespace vnr::test
