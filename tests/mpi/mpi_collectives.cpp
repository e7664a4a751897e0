// Run under `mpirun -n N` (ctest mpi_collectives_n2, _n4): the MPI layer's collectives on real ranks,
// each checked against a one-process reference. Argument: a scratch directory. Exit 0 when every check
// passes on every rank; each failed check prints "rank R: FAIL ...".
#include <sys/stat.h>
#include <algorithm>
#include <cstdio>
#include <fstream>
#include <random>
#include <sstream>
#include "mpi/comm.h"
#include "mpi/parallel_file.h"
#include "mpi/sort_last.h"
#include "vnr/fileio.h"

using namespace vnr;
using namespace vnr::mpi;

namespace {
int g_failures = 0;
void expect(bool ok, const std::string& what) {
  if (ok) return;
  ++g_failures;
  std::fprintf(stderr, "rank %d: FAIL %s\n", rank(), what.c_str());
}

// Rank size-1 throws naming a brick: every rank gets the same RankFailure, and the job goes on.
void check_error_agreement() {
  const int last = size() - 1;
  std::string seen;
  try {
    agree("training", [&] {
      if (rank() == last) fail("brick 3 (x 0..16): cannot read 'vol.raw'");
    });
  } catch (const RankFailure& e) {
    seen = e.what();
  }
  const std::string want = fmt::format("rank {} of {} failed training: brick 3 (x 0..16): cannot read 'vol.raw'", last, size());
  expect(seen == want, "agree() said '" + seen + "', not '" + want + "'");
  // Two failing ranks of more: the lower one speaks, the count says there was another.
  seen.clear();
  try {
    agree("decoding", [&] {
      if (size() > 2 && rank() >= size() - 2) fail("out of disk");
    });
  } catch (const RankFailure& e) {
    seen = e.what();
  }
  if (size() > 2)
    expect(seen.find(fmt::format("rank {} of", size() - 2)) == 0 && seen.find("1 other rank failed too") != std::string::npos,
           "two failures reported as '" + seen + "'");
  // Every rank failing (a missing file): said once for all.
  seen.clear();
  try {
    agree("opening", [&] { fail("cannot open 'x'"); });
  } catch (const RankFailure& e) {
    seen = e.what();
  }
  expect(seen == fmt::format("all {} ranks failed opening: cannot open 'x'", size()), "all failed: '" + seen + "'");
  bool threw = false;
  try {
    agree("nothing", [] {});
  } catch (const RankFailure&) {
    threw = true;
  }
  expect(!threw, "agree() threw without a failure");
  expect(sum(int64_t(rank() + 1)) == int64_t(size()) * (size() + 1) / 2, "sum");
  expect(broadcast(rank() == 0 ? "hello" : "", 0) == "hello", "broadcast");
  const std::vector<std::string> texts = gather(std::string(size_t(rank()), char('a' + rank())));
  for (int r = 0; r < size() && rank() == 0; ++r)
    expect(texts.size() == size_t(size()) && texts[size_t(r)] == std::string(size_t(r), char('a' + r)), "gather");
}

// Each rank writes an uneven slab of a byte pattern; the committed file is the pattern, no temporary left.
void check_parallel_file(const std::string& dir) {
  const std::string path = dir + "/pattern.bin";
  const uint64_t total = 1000003;
  std::vector<char> expected(total);
  for (uint64_t i = 0; i < total; ++i) expected[i] = char((i * 2654435761u) >> 13);
  const uint64_t b0 = total * uint64_t(rank()) / uint64_t(size()), b1 = total * uint64_t(rank() + 1) / uint64_t(size());
  std::string tmp;
  {
    ParallelFile f(path, total);
    tmp = f.temporary_path();
    f.write_at(b0, expected.data() + b0, b1 - b0);
    f.commit();
  }
  barrier();
  if (rank() == 0) {
    expect(read_file(path) == std::string(expected.begin(), expected.end()), "the parallel file's bytes");
    expect(!file_exists(tmp), "temporary left after commit");
  }
  // A rank failing before commit: the old file stays, the temporary goes.
  bool threw = false;
  try {
    ParallelFile f(path, 10);
    tmp = f.temporary_path();
    agree("writing", [&] {
      if (rank() == size() - 1) fail("disk full");
      f.write_at(0, "0123456789", 10);
    });
    f.commit();
  } catch (const RankFailure&) {
    threw = true;
  }
  barrier();
  expect(threw, "a failed write did not throw on every rank");
  if (rank() == 0) {
    expect(file_size(path) == total, "the old file was replaced by a failed write");
    expect(!file_exists(tmp), "temporary left after a failed write");
  }
}

// Random premultiplied brick images spread over the ranks; rank 0's composite is the one-process one, bit for bit.
void check_direct_send() {
  const int n_bricks = 7, w = 13, h = 11;
  std::vector<Image> imgs(n_bricks, Image(w, h));
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(0, 1);
  for (Image& img : imgs)
    for (Vec4f& p : img.pixels) {
      const float a = u(rng) < 0.3f ? 0.0f : u(rng);
      p = {a * u(rng), a * u(rng), a * u(rng), a};
    }
  std::vector<int> owner(n_bricks), order = {5, 2, 6, 0, 3, 1, 4};
  std::vector<BrickImage> mine;
  for (int b = 0; b < n_bricks; ++b) {
    owner[size_t(b)] = (b * 3) % size();  // uneven: some ranks hold none when size() > 3
    if (owner[size_t(b)] == rank()) mine.push_back({b, &imgs[size_t(b)]});
  }
  CompositeStats stats;
  Image got = composite_direct_send(mine, owner, order, w, h, &stats);
  if (rank() != 0) return;
  Image want = composite_in_order(imgs, order);
  bool same = got.width == w && got.height == h;
  for (size_t i = 0; same && i < want.pixels.size(); ++i)
    same = got.pixels[i].x == want.pixels[i].x && got.pixels[i].y == want.pixels[i].y &&
           got.pixels[i].z == want.pixels[i].z && got.pixels[i].w == want.pixels[i].w;
  expect(same, "direct send differs from compositing in one process");
}

// Every rank of the test runs on this one node: the ranks on the node are all of them, and their local
// ranks (which spread a node's ranks over its GPUs) are 0..size-1, each once.
void check_local_ranks() {
  expect(local_size() == size(), "local_size() is the job's size on one node");
  std::vector<int64_t> local = all_gather(int64_t(local_rank()));
  std::sort(local.begin(), local.end());
  for (int r = 0; r < size(); ++r) expect(local[size_t(r)] == r, "local ranks are 0..size-1, each once");
}
}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: mpirun -n N mpi_collectives SCRATCH_DIR\n");
    return 2;
  }
  Session session(&argc, &argv);
  const std::string dir = argv[1];
  if (rank() == 0) ::mkdir(dir.c_str(), 0755);
  barrier();
  try {
    check_local_ranks();
    check_error_agreement();
    check_parallel_file(dir);
    check_direct_send();
  } catch (const std::exception& e) {
    expect(false, std::string("unexpected error: ") + e.what());
  }
  const int64_t failures = sum(int64_t(g_failures));
  if (rank() == 0) std::printf("%s: %lld failed checks on %d ranks\n", failures ? "FAILED" : "passed", (long long)failures, size());
  return failures ? 1 : 0;
}
