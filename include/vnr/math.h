#pragma once
#include <cmath>
#include <cstdint>
#include "vnr/hd.h"

namespace vnr {

// Volume dimensions (x fastest in memory).
struct Int3 {
  int64_t x = 0, y = 0, z = 0;
  VNR_HD int64_t& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
  VNR_HD int64_t operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
  VNR_HD uint64_t count() const { return uint64_t(x) * uint64_t(y) * uint64_t(z); }
  friend bool operator==(const Int3&, const Int3&) = default;
};

struct Vec3f {
  float x = 0, y = 0, z = 0;
  VNR_HD float operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
};

VNR_HD inline float clampf(float v, float lo, float hi) { return v < lo ? lo : (v > hi ? hi : v); }

// Small vector algebra for per-ray code (cameras, lights, ray-box tests).
VNR_HD inline Vec3f operator+(Vec3f a, Vec3f b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
VNR_HD inline Vec3f operator-(Vec3f a, Vec3f b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
VNR_HD inline Vec3f operator-(Vec3f a) { return {-a.x, -a.y, -a.z}; }
VNR_HD inline Vec3f operator*(Vec3f a, float s) { return {a.x * s, a.y * s, a.z * s}; }
VNR_HD inline Vec3f operator*(float s, Vec3f a) { return {a.x * s, a.y * s, a.z * s}; }
VNR_HD inline Vec3f operator*(Vec3f a, Vec3f b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
VNR_HD inline float dot(Vec3f a, Vec3f b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
VNR_HD inline Vec3f cross(Vec3f a, Vec3f b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
VNR_HD inline float length(Vec3f a) { return sqrtf(dot(a, a)); }
VNR_HD inline Vec3f normalize(Vec3f a) {
  float l = length(a);
  return l > 0 ? a * (1.0f / l) : a;
}
VNR_HD inline float max_component(Vec3f a) { return a.x > a.y ? (a.x > a.z ? a.x : a.z) : (a.y > a.z ? a.y : a.z); }

// RGBA colour (straight or premultiplied, as the user says).
struct Vec4f {
  float x = 0, y = 0, z = 0, w = 0;
  VNR_HD Vec3f rgb() const { return {x, y, z}; }
};

inline uint64_t next_multiple(uint64_t v, uint64_t m) { return (v + m - 1) / m * m; }

// A box of voxels [lo, hi) of a grid.
struct Box3 {
  Int3 lo, hi;
  VNR_HD Int3 size() const { return Int3{hi.x - lo.x, hi.y - lo.y, hi.z - lo.z}; }
  VNR_HD uint64_t voxels() const { return size().count(); }
  VNR_HD bool empty() const { return hi.x <= lo.x || hi.y <= lo.y || hi.z <= lo.z; }
  friend bool operator==(const Box3&, const Box3&) = default;
};

}  // namespace vnr
