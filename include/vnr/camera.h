#pragma once
// vnr's camera: a pinhole camera (docs/semantics.md B.10) in the world space of B.2, where the volume
// box spans [0, box] with box = dims * spacing (voxel units), and the cameras a front end asks for.
#include <optional>
#include <utility>
#include "vnr/math.h"

namespace vnr {

struct Camera {
  Vec3f eye{0, 0, 1};
  Vec3f center{0, 0, 0};
  Vec3f up{0, 1, 0};
  float fovy = 45;  // vertical field of view, degrees
};

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
