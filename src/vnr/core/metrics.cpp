#include "vnr/metrics.h"
#include <algorithm>
#include <cmath>
#include <vector>
#include "vnr/core/parallel.h"

namespace vnr {

ErrorStats error_stats(const float* reference, const float* test, Int3 dims) {
  const int64_t n = int64_t(dims.count());
  constexpr int64_t grain = 1 << 16;
  struct Part {
    double se = 0, max_abs = 0;
  };
  // Per-range partials summed in index order: the result does not depend on the thread count.
  std::vector<Part> parts(size_t(std::max<int64_t>(1, (n + grain - 1) / grain)));
  parallel_for_range(n, grain, [&](int64_t b, int64_t e) {
    Part p;
    for (int64_t i = b; i < e; ++i) {
      double d = double(test[i]) - double(reference[i]);
      p.se += d * d;
      p.max_abs = std::max(p.max_abs, std::fabs(d));
    }
    parts[size_t(b / grain)] = p;
  });
  ErrorStats s;
  double se = 0;
  for (auto& p : parts) {
    se += p.se;
    s.max_abs_error = std::max(s.max_abs_error, p.max_abs);
  }
  s.mse = n > 0 ? se / double(n) : 0;
  s.psnr = s.mse > 0 ? 10 * std::log10(1 / s.mse) : 999.0;
  return s;
}

namespace {

// x pass of ssim3d: running sums of a, b, a^2, b^2, ab over windows of wx along each of `rows_in`
// rows of slice z starting at row y0; rows[(q * rows_in + r) * ox + x] is sum q of row r's window x.
void row_window_sums(const float* reference, const float* test, int64_t nx, int64_t ny, int64_t z, int64_t y0,
                     int64_t rows_in, int64_t wx, int64_t ox, double* rows) {
  for (int64_t r = 0; r < rows_in; ++r) {
    const float* a = reference + (z * ny + y0 + r) * nx;
    const float* b = test + (z * ny + y0 + r) * nx;
    double s[5] = {0, 0, 0, 0, 0};
    auto add = [&](int64_t x, double sign) {
      double va = a[x], vb = b[x];
      s[0] += sign * va;
      s[1] += sign * vb;
      s[2] += sign * va * va;
      s[3] += sign * vb * vb;
      s[4] += sign * va * vb;
    };
    for (int64_t x = 0; x < wx; ++x) add(x, 1);
    for (int64_t x = 0; x < ox; ++x) {
      if (x > 0) {
        add(x - 1, -1);
        add(x + wx - 1, 1);
      }
      for (int q = 0; q < 5; ++q) rows[size_t((q * rows_in + r) * ox + x)] = s[q];
    }
  }
}

// y pass of ssim3d: running sums of wy rows down the columns into `ny_out` window rows per sum,
// vectorisable over x; out[q * ny_out * ox + j * ox + x].
void column_window_sums(const double* rows, int64_t rows_in, int64_t wy, int64_t ox, int64_t ny_out, double* sl) {
  const int64_t P = ox * ny_out;
  for (int q = 0; q < 5; ++q) {
    const double* rq = rows + q * rows_in * ox;
    double* out = sl + q * P;
    for (int64_t x = 0; x < ox; ++x) out[x] = 0;
    for (int64_t r = 0; r < wy; ++r)
      for (int64_t x = 0; x < ox; ++x) out[x] += rq[r * ox + x];
    for (int64_t j = 1; j < ny_out; ++j) {
      const double* prev = out + (j - 1) * ox;
      const double* leave = rq + (j - 1) * ox;
      const double* enter = rq + (j + wy - 1) * ox;
      double* cur = out + j * ox;
      for (int64_t x = 0; x < ox; ++x) cur[x] = prev[x] - leave[x] + enter[x];
    }
  }
}

}  // namespace

// Box sums of a, b, a^2, b^2, ab over every window position, built separably (x, then y per
// slice, then a running sum over z slices), so the cost per voxel is independent of the window.
// The windows are cut into fixed tiles of output rows x output slices: memory per tile stays small
// for any volume size, and because the tiling does not depend on the thread count neither does
// the result (tile sums are added in tile order).
double ssim3d(const float* reference, const float* test, Int3 dims) {
  const int64_t nx = dims.x, ny = dims.y, nz = dims.z;
  if (nx <= 0 || ny <= 0 || nz <= 0) return 1.0;
  const int64_t wx = std::min<int64_t>(7, nx), wy = std::min<int64_t>(7, ny), wz = std::min<int64_t>(7, nz);
  const int64_t ox = nx - wx + 1, oy = ny - wy + 1, oz = nz - wz + 1;
  const double wn = double(wx * wy * wz);
  const double c1 = 0.01 * 0.01, c2 = 0.03 * 0.03;
  const double inv_n = 1.0 / wn, inv_n1 = wn > 1 ? 1.0 / (wn - 1) : 0.0;

  constexpr int64_t kTileY = 64, kTileZ = 64;  // output windows per tile; the overlap is w - 1 rows per tile
  const int64_t tiles_y = (oy + kTileY - 1) / kTileY, tiles_z = (oz + kTileZ - 1) / kTileZ;
  std::vector<double> sums(size_t(tiles_y * tiles_z), 0.0);

  parallel_for(tiles_y * tiles_z, [&](int64_t tile) {
    const int64_t y0 = (tile % tiles_y) * kTileY, y1 = std::min(oy, y0 + kTileY);
    const int64_t z0 = (tile / tiles_y) * kTileZ, z1 = std::min(oz, z0 + kTileZ);
    const int64_t rows_in = y1 - y0 + wy - 1;  // input rows the tile's windows cover
    const int64_t P = ox * (y1 - y0);           // windows per slice in this tile
    std::vector<double> ring(size_t(wz * 5 * P)), acc(size_t(5 * P), 0.0), rows(size_t(5 * ox * rows_in));
    double total = 0;
    for (int64_t z = z0; z < z1 + wz - 1; ++z) {
      double* sl = ring.data() + (z % wz) * 5 * P;
      if (z - z0 >= wz)  // this slot holds the slice that just left the window
        for (int64_t i = 0; i < 5 * P; ++i) acc[size_t(i)] -= sl[i];

      row_window_sums(reference, test, nx, ny, z, y0, rows_in, wx, ox, rows.data());
      column_window_sums(rows.data(), rows_in, wy, ox, y1 - y0, sl);
      for (int64_t i = 0; i < 5 * P; ++i) acc[size_t(i)] += sl[i];

      if (z - z0 >= wz - 1) {  // windows starting at z - wz + 1 are complete
        const double* sa = acc.data();
        const double* sb = sa + P;
        const double* saa = sb + P;
        const double* sbb = saa + P;
        const double* sab = sbb + P;
        for (int64_t i = 0; i < P; ++i) {
          double ma = sa[i] * inv_n, mb = sb[i] * inv_n;
          double va = (saa[i] - sa[i] * ma) * inv_n1;
          double vb = (sbb[i] - sb[i] * mb) * inv_n1;
          double cov = (sab[i] - sa[i] * mb) * inv_n1;
          total += ((2 * ma * mb + c1) * (2 * cov + c2)) / ((ma * ma + mb * mb + c1) * (va + vb + c2));
        }
      }
    }
    sums[size_t(tile)] = total;
  });
  double total = 0;
  for (double s : sums) total += s;
  return total / double(ox * oy * oz);
}

}  // namespace vnr
