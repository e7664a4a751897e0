#include "mpi/sort_last.h"
#include <mpi.h>
#include <chrono>
#include <map>
#include "mpi/comm.h"
#include "vnr/error.h"

namespace vnr::mpi {

namespace {
const Vec4f* band_of(const Image& img, RowBand band) { return img.pixels.data() + size_t(band.y0) * img.width; }

// Sends this rank's brick bands to their owners and receives every brick's band of this rank's rows.
std::map<int, std::vector<Vec4f>> exchange_bands(const std::vector<BrickImage>& mine,
                                                 const std::vector<int>& owner_of_brick, int width, int height,
                                                 CompositeStats& stats) {
  const int me = rank(), n = size();
  const RowBand my_band = row_band(height, me, n);
  const size_t my_count = size_t(my_band.rows()) * width;
  std::map<int, std::vector<Vec4f>> received;
  std::vector<MPI_Request> requests;
  // Receives first, in brick order per source: MPI keeps the order of messages between two ranks.
  for (size_t b = 0; b < owner_of_brick.size(); ++b) {
    std::vector<Vec4f>& buf = received[int(b)];
    buf.resize(my_count);
    if (owner_of_brick[b] == me || my_count == 0) continue;
    requests.emplace_back();
    check_mpi(MPI_Irecv(buf.data(), int(my_count * 4), MPI_FLOAT, owner_of_brick[b], 1, MPI_COMM_WORLD, &requests.back()),
          "receive");
  }
  std::map<int, const Image*> by_brick;
  for (const BrickImage& bi : mine) by_brick[bi.brick] = bi.image;
  for (const auto& [brick, img] : by_brick) {
    for (int dest = 0; dest < n; ++dest) {
      const RowBand band = row_band(height, dest, n);
      const size_t count = size_t(band.rows()) * width;
      if (count == 0) continue;
      if (dest == me) {
        std::copy(band_of(*img, band), band_of(*img, band) + count, received[brick].begin());
        continue;
      }
      requests.emplace_back();
      check_mpi(MPI_Isend(band_of(*img, band), int(count * 4), MPI_FLOAT, dest, 1, MPI_COMM_WORLD, &requests.back()),
            "send");
      stats.bytes_sent += int64_t(count * sizeof(Vec4f));
    }
  }
  check_mpi(MPI_Waitall(int(requests.size()), requests.data(), MPI_STATUSES_IGNORE), "wait");
  return received;
}
}  // namespace

Image composite_direct_send(const std::vector<BrickImage>& mine, const std::vector<int>& owner_of_brick,
                            const std::vector<int>& order, int width, int height, CompositeStats* stats) {
  const auto t0 = std::chrono::steady_clock::now();
  CompositeStats local;
  for (const BrickImage& bi : mine) {
    if (!bi.image || bi.image->width != width || bi.image->height != height)
      fail("composite: brick {}'s image is not {}x{}", bi.brick, width, height);
    if (bi.brick < 0 || size_t(bi.brick) >= owner_of_brick.size() || owner_of_brick[size_t(bi.brick)] != rank())
      fail("composite: brick {} is not this rank's", bi.brick);
  }
  Image result;
  if (!active()) {
    std::vector<Image> images(owner_of_brick.size(), Image(width, height));
    for (const BrickImage& bi : mine) images[size_t(bi.brick)] = *bi.image;
    result = composite_in_order(images, order);
  } else {
    std::map<int, std::vector<Vec4f>> bands = exchange_bands(mine, owner_of_brick, width, height, local);
    const RowBand my_band = row_band(height, rank(), size());
    std::vector<Vec4f> acc(size_t(my_band.rows()) * width);
    for (int b : order) composite_behind(acc.data(), bands.at(b).data(), acc.size());
    // Rank 0 gathers the bands (in rank order, which is row order).
    const size_t n_ranks = static_cast<size_t>(size());
    std::vector<int> counts(n_ranks), offsets(n_ranks);
    for (int r = 0; r < size(); ++r) {
      const RowBand band = row_band(height, r, size());
      counts[size_t(r)] = band.rows() * width * 4;
      offsets[size_t(r)] = band.y0 * width * 4;
    }
    if (rank() == 0) result = Image(width, height);
    check_mpi(MPI_Gatherv(acc.data(), int(acc.size() * 4), MPI_FLOAT, rank() == 0 ? result.pixels.data() : nullptr,
                      counts.data(), offsets.data(), MPI_FLOAT, 0, MPI_COMM_WORLD),
          "gather");
    if (rank() != 0) local.bytes_sent += int64_t(acc.size() * sizeof(Vec4f));
  }
  local.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (stats) *stats = local;
  return result;
}

}  // namespace vnr::mpi
