#pragma once
#include <optional>
#include <utility>
// Pinhole camera (docs/semantics.md B.10) in the world space of B.2: the volume box spans [0, box] with
// box = dims * spacing (voxel units), so a step of 1 is one voxel.
#include "vnr/hd.h"
#include "vnr/math.h"

namespace vnr {

struct Camera {
  Vec3f eye{0, 0, 1};
  Vec3f center{0, 0, 0};
  Vec3f up{0, 1, 0};
  float fovy = 45;  // vertical field of view, degrees
};

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

// A camera that looks at the centre of the box [0, box] from azimuth (degrees, about +y, 0 = from +z)
// and elevation (degrees above the xz plane), far enough that the bounding sphere of the voxel
// centres fits the vertical field of view: VTK's ResetCamera rule (distance = r / sin(fovy / 2),
// r = |box - 1| / 2), so images line up with the VTK peer's.
Camera orbit_camera(Vec3f box, float azimuth_deg, float elevation_deg = 0, float fovy_deg = 30);

// The camera a front end asks for (vnr render's --eye/--center/--up/--fovy/--orbit, Python's camera=):
// eye and center together (with up and fovy), else an orbit (azimuth, elevation in degrees, elevation
// in (-90, 90)) around the box, else `fallback` (a scene's camera) when it has one, else orbit (0, 0).
struct CameraRequest {
  std::optional<Vec3f> eye, center;
  Vec3f up{0, 1, 0};
  float fovy = 30;
  std::optional<std::pair<float, float>> orbit;  // azimuth, elevation
};
Camera camera_for(const CameraRequest& request, Vec3f box, const std::optional<Camera>& fallback = std::nullopt);

}  // namespace vnr
