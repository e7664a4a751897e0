#include "vnr/render/camera.h"
#include <cmath>
#include "vnr/error.h"

namespace vnr {

namespace {

constexpr float kPi = 3.14159265358979323846f;

bool finite3(Vec3f v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

}  // namespace

CameraFrame make_camera_frame(const Camera& cam, int width, int height) {
  if (width <= 0 || height <= 0) fail("camera: image size {}x{} is not positive", width, height);
  if (!finite3(cam.eye) || !finite3(cam.center) || !finite3(cam.up))
    fail("camera: eye, center and up must be finite numbers");
  if (!(cam.fovy > 0 && cam.fovy < 180))
    fail("camera: fovy {} degrees is outside (0, 180)", cam.fovy);
  const Vec3f view = cam.center - cam.eye;
  const float dist = length(view);
  if (!(dist > 0)) fail("camera: eye and center are the same point ({}, {}, {})", cam.eye.x, cam.eye.y, cam.eye.z);
  const float up_len = length(cam.up);
  if (!(up_len > 0)) fail("camera: up vector is zero");
  const Vec3f dir = view * (1.0f / dist);
  const Vec3f r = cross(dir, cam.up * (1.0f / up_len));
  // |r| = sin(angle between dir and up); below ~1e-4 rad the frame is numerically meaningless.
  if (!(length(r) > 1e-4f))
    fail("camera: up vector ({}, {}, {}) is parallel to the viewing direction", cam.up.x, cam.up.y, cam.up.z);
  const Vec3f right = normalize(r);
  const Vec3f true_up = cross(right, dir);  // unit: right and dir are orthonormal
  const float span = 2.0f * std::tan(cam.fovy * (kPi / 360.0f));
  const float aspect = float(width) / float(height);
  CameraFrame f;
  f.eye = cam.eye;
  f.dir = dir;
  f.du = right * (span * aspect);
  f.dv = true_up * span;
  f.width = width;
  f.height = height;
  return f;
}

Camera orbit_camera(Vec3f box, float azimuth_deg, float elevation_deg, float fovy_deg) {
  if (!finite3(box) || !(box.x > 0 && box.y > 0 && box.z > 0))
    fail("orbit camera: box ({}, {}, {}) must be positive", box.x, box.y, box.z);
  if (!(fovy_deg > 0 && fovy_deg < 180)) fail("orbit camera: fovy {} degrees is outside (0, 180)", fovy_deg);
  if (!std::isfinite(azimuth_deg) || !std::isfinite(elevation_deg))
    fail("orbit camera: azimuth and elevation must be finite");
  // VTK's ResetCamera: the bounding sphere of the bounds (voxel centres span box - 1) fills the
  // vertical view angle; a degenerate (single-voxel) box gets radius 0.5 as in VTK.
  const Vec3f ext{box.x - 1, box.y - 1, box.z - 1};
  float r = 0.5f * length(ext);
  if (!(r > 0)) r = 0.5f;
  const float dist = r / std::sin(fovy_deg * (kPi / 360.0f));
  const float a = azimuth_deg * (kPi / 180.0f), e = elevation_deg * (kPi / 180.0f);
  // Azimuth rotates about +y (0 = on +z, 90 = on +x, VTK's Azimuth direction); elevation lifts
  // toward +y. `up` is the derivative of the view position with respect to elevation: orthogonal to
  // the view direction and pointing up, so the frame stays valid even at +-90 degrees.
  const Vec3f offset{std::cos(e) * std::sin(a), std::sin(e), std::cos(e) * std::cos(a)};
  Camera c;
  c.center = box * 0.5f;
  c.eye = c.center + offset * dist;
  c.up = Vec3f{-std::sin(e) * std::sin(a), std::cos(e), -std::sin(e) * std::cos(a)};
  c.fovy = fovy_deg;
  return c;
}

Camera camera_for(const CameraRequest& r, Vec3f box, const std::optional<Camera>& fallback) {
  if (r.eye || r.center) {
    if (!r.eye || !r.center) fail("the camera's eye and center go together");
    return Camera{*r.eye, *r.center, r.up, r.fovy};
  }
  if (!r.orbit && fallback) return *fallback;
  const auto [azimuth, elevation] = r.orbit.value_or(std::make_pair(0.f, 0.f));
  if (!std::isfinite(azimuth) || !std::isfinite(elevation) || elevation <= -90 || elevation >= 90)
    fail("an orbit camera takes an azimuth and an elevation in degrees, the elevation in (-90, 90); got {}, {}",
         azimuth, elevation);
  return orbit_camera(box, azimuth, elevation, r.fovy);
}

}  // namespace vnr
