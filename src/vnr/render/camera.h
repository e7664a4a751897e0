#pragma once
// The renderer's side of the camera (vnr/camera.h): the frame per-ray code generates primary rays from.
#include "vnr/camera.h"
#include "vnr/hd.h"
#include "vnr/math.h"

namespace vnr {

// What per-ray code needs to generate primary rays for a W x H image. Pixel (ix, iy) with iy = 0
// the top row and sub-pixel offset (jx, jy) in [0,1) looks along
// normalize(dir + (sx - 0.5) * du + (0.5 - sy) * dv), sx = (ix + jx) / W, sy = (iy + jy) / H.
struct CameraFrame {
  Vec3f eye, dir, du, dv;  // du spans the image width, dv the height (pointing up)
  int width = 0, height = 0;
};

CameraFrame make_camera_frame(const Camera& cam, int width, int height);

VNR_HD VNR_INLINE Vec3f camera_ray_dir(const CameraFrame& f, int ix, int iy, float jx, float jy) {
  float sx = (float(ix) + jx) / float(f.width), sy = (float(iy) + jy) / float(f.height);
  return normalize(f.dir + (sx - 0.5f) * f.du + (0.5f - sy) * f.dv);
}

}  // namespace vnr
