// The scene that the grid image tests of both renderers share (tests/test_render.cpp: streaming vs
// in-shader on the CPU; tests/test_gpu_render.cpp: GPU vs CPU). Header-only, in vnr::test.
#pragma once

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

}  // namespace vnr::test
