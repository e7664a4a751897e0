#include "vnr/volume/wavelet.h"
#include <array>
#include "vnr/error.h"
#include "vnr/core/parallel.h"

namespace vnr {

namespace {

// Lifting steps and scale of CDF 9/7 (Daubechies & Sweldens 1998, "Factoring wavelet transforms into
// lifting steps"); with low *= K and high /= K the transform is close to orthonormal, so an error
// spread over the coefficients reaches the voxels at about the same mean square.
constexpr double kAlpha = -1.586134342059924, kBeta = -0.052980118572961, kGamma = 0.882911075530934,
                 kDelta = 0.443506852043971, kScale = 1.149604398860241;

// The lifting steps on s (ceil(n/2) even samples) and d (floor(n/2) odd ones); indices clamped to
// their band are the whole-sample symmetric extension at both ends, for even and odd n alike.
void predict(double* d, const double* s, int64_t nd, int64_t ns, double w) {
  for (int64_t i = 0; i < nd; ++i) d[i] += w * (s[i] + s[std::min(i + 1, ns - 1)]);
}
void update(double* s, const double* d, int64_t ns, int64_t nd, double w) {
  for (int64_t i = 0; i < ns; ++i) s[i] += w * (d[std::max<int64_t>(i - 1, 0)] + d[std::min(i, nd - 1)]);
}

// One line of n >= 2 samples (in line), to [low | high] and back; tmp holds n values.
void forward_line(double* line, int64_t n, double* tmp) {
  const int64_t ns = (n + 1) / 2, nd = n / 2;
  double *s = tmp, *d = tmp + ns;
  for (int64_t i = 0; i < ns; ++i) s[i] = line[2 * i];
  for (int64_t i = 0; i < nd; ++i) d[i] = line[2 * i + 1];
  predict(d, s, nd, ns, kAlpha);
  update(s, d, ns, nd, kBeta);
  predict(d, s, nd, ns, kGamma);
  update(s, d, ns, nd, kDelta);
  for (int64_t i = 0; i < ns; ++i) line[i] = s[i] * kScale;
  for (int64_t i = 0; i < nd; ++i) line[ns + i] = d[i] / kScale;
}
void inverse_line(double* line, int64_t n, double* tmp) {
  const int64_t ns = (n + 1) / 2, nd = n / 2;
  double *s = tmp, *d = tmp + ns;
  for (int64_t i = 0; i < ns; ++i) s[i] = line[i] / kScale;
  for (int64_t i = 0; i < nd; ++i) d[i] = line[ns + i] * kScale;
  update(s, d, ns, nd, -kDelta);
  predict(d, s, nd, ns, -kGamma);
  update(s, d, ns, nd, -kBeta);
  predict(d, s, nd, ns, -kAlpha);
  for (int64_t i = 0; i < ns; ++i) line[2 * i] = s[i];
  for (int64_t i = 0; i < nd; ++i) line[2 * i + 1] = d[i];
}

// Every line along `axis` of the box [0, box) of a grid of dims, each gathered, lifted, scattered.
void lift_axis(std::vector<float>& v, Int3 dims, std::array<int64_t, 3> box, int axis, bool inverse) {
  const std::array<int64_t, 3> stride = {1, dims.x, dims.x * dims.y};
  const int a1 = axis == 0 ? 1 : 0, a2 = axis == 2 ? 1 : 2;
  const int64_t n = box[axis];
  parallel_for(box[a2], [&](int64_t j2) {
    std::vector<double> line(static_cast<size_t>(n)), tmp(static_cast<size_t>(n));
    for (int64_t j1 = 0; j1 < box[a1]; ++j1) {
      float* base = v.data() + j1 * stride[a1] + j2 * stride[a2];
      for (int64_t i = 0; i < n; ++i) line[size_t(i)] = base[i * stride[axis]];
      if (inverse) inverse_line(line.data(), n, tmp.data());
      else forward_line(line.data(), n, tmp.data());
      for (int64_t i = 0; i < n; ++i) base[i * stride[axis]] = float(line[size_t(i)]);
    }
  });
}

// The low band's box at each level: boxes[0] = dims; an axis splits while it has kWaveletMinLength.
std::vector<std::array<int64_t, 3>> level_boxes(Int3 dims, int levels) {
  std::vector<std::array<int64_t, 3>> boxes = {{dims.x, dims.y, dims.z}};
  for (int l = 0; l < levels; ++l) {
    auto next = boxes.back();
    for (auto& n : next)
      if (n >= kWaveletMinLength) n = (n + 1) / 2;
    boxes.push_back(next);
  }
  return boxes;
}

void check(const std::vector<float>& values, Int3 dims, int levels) {
  if (values.size() != size_t(dims.count())) fail("wavelet: {} values for {} voxels", values.size(), dims.count());
  if (levels < 0 || levels > wavelet_levels(dims)) fail("wavelet: {} levels for dims {}x{}x{}", levels, dims.x, dims.y, dims.z);
}

}  // namespace

int wavelet_levels(Int3 dims) {
  int levels = 0;
  for (auto box = level_boxes(dims, kWaveletMaxLevels); levels < kWaveletMaxLevels; ++levels)
    if (box[size_t(levels)] == box[size_t(levels) + 1]) break;
  return levels;
}

void wavelet_forward(std::vector<float>& values, Int3 dims, int levels) {
  check(values, dims, levels);
  const auto boxes = level_boxes(dims, levels);
  for (int l = 0; l < levels; ++l)
    for (int axis = 0; axis < 3; ++axis)
      if (boxes[size_t(l)][size_t(axis)] >= kWaveletMinLength) lift_axis(values, dims, boxes[size_t(l)], axis, false);
}

void wavelet_inverse(std::vector<float>& values, Int3 dims, int levels) {
  check(values, dims, levels);
  const auto boxes = level_boxes(dims, levels);
  for (int l = levels - 1; l >= 0; --l)
    for (int axis = 2; axis >= 0; --axis)
      if (boxes[size_t(l)][size_t(axis)] >= kWaveletMinLength) lift_axis(values, dims, boxes[size_t(l)], axis, true);
}

std::vector<uint8_t> wavelet_coefficient_levels(Int3 dims, int levels) {
  if (levels < 0 || levels > wavelet_levels(dims)) fail("wavelet: {} levels for dims {}x{}x{}", levels, dims.x, dims.y, dims.z);
  const auto boxes = level_boxes(dims, levels);
  std::vector<uint8_t> level(size_t(dims.count()));
  parallel_for(dims.z, [&](int64_t z) {
    for (int64_t y = 0; y < dims.y; ++y)
      for (int64_t x = 0; x < dims.x; ++x) {
        int l = 0;  // inside the next level's low box: one level coarser
        while (l < levels && x < boxes[size_t(l) + 1][0] && y < boxes[size_t(l) + 1][1] && z < boxes[size_t(l) + 1][2]) ++l;
        level[size_t(x + dims.x * (y + dims.y * z))] = uint8_t(l);
      }
  });
  return level;
}

}  // namespace vnr
