// AMX bf16 throughput probe (not part of libvnr): one 64x64 MLP layer (the paper config's hidden layer)
// over a 256-sample chunk, bf16 weights and activations in vnr's pair layout, fp32 sums, with tile
// loads and stores, on one thread. Measures what an AMX backend for the batched MLP could reach on an
// Intel Xeon with AMX (docs/benchmarks.md "CUDA backend": the GPU machine's CPU). Linux only (asks the kernel for
// the tile state). Build and run:
//   g++ -O2 -mamx-tile -mamx-bf16 bench/probes/amx_probe.cpp -o amx_probe && ./amx_probe [REPS]
#include <immintrin.h>
#include <sys/syscall.h>
#include <unistd.h>
#include <chrono>
#include <cstdio>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <vector>
struct TileCfg { uint8_t palette, start; uint8_t res[14]; uint16_t colsb[16]; uint8_t rows[16]; };
int main(int argc, char** argv) {
  if (syscall(SYS_arch_prctl, 0x1023 /*ARCH_REQ_XCOMP_PERM*/, 18 /*XFEATURE_XTILEDATA*/)) { std::puts("amx_probe: this CPU or kernel offers no AMX tile state"); return 1; }
  const int M = 64, K = 64, N = 256;  // outputs, inputs, samples
  // A: weights M x K bf16 row-major (tile: 16 rows x 32 bf16); B: activations in pair layout (K/2 rows x N pairs)
  std::vector<uint16_t> A(M * K, 0x3f80), B(K * N, 0x3f80);
  std::vector<float> C(M * N);
  TileCfg cfg; memset(&cfg, 0, sizeof cfg); cfg.palette = 1;
  for (int t = 0; t < 8; ++t) { cfg.colsb[t] = 64; cfg.rows[t] = 16; }
  _tile_loadconfig(&cfg);
  const int reps = argc > 1 ? atoi(argv[1]) : 20000;
  auto t0 = std::chrono::steady_clock::now();
  for (int r = 0; r < reps; ++r) {
    for (int n0 = 0; n0 < N; n0 += 32) {          // two 16-sample column tiles at a time
      for (int m0 = 0; m0 < M; m0 += 32) {        // two 16-row tiles: 4 accumulators (tmm0-3)
        _tile_zero(0); _tile_zero(1); _tile_zero(2); _tile_zero(3);
        for (int k0 = 0; k0 < K; k0 += 32) {
          _tile_loadd(4, &A[(m0) * K + k0], K * 2);
          _tile_loadd(5, &A[(m0 + 16) * K + k0], K * 2);
          _tile_loadd(6, &B[(k0 / 2) * N * 2 + n0 * 2], N * 4);
          _tile_loadd(7, &B[(k0 / 2) * N * 2 + (n0 + 16) * 2], N * 4);
          _tile_dpbf16ps(0, 4, 6); _tile_dpbf16ps(1, 4, 7); _tile_dpbf16ps(2, 5, 6); _tile_dpbf16ps(3, 5, 7);
        }
        _tile_stored(0, &C[m0 * N + n0], N * 4); _tile_stored(1, &C[m0 * N + n0 + 16], N * 4);
        _tile_stored(2, &C[(m0 + 16) * N + n0], N * 4); _tile_stored(3, &C[(m0 + 16) * N + n0 + 16], N * 4);
      }
    }
  }
  double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  _tile_release();
  printf("AMX bf16 64x64 layer, 256 samples: %.1f GFLOP/s on one thread (C[0]=%g, expect %d)\n", 2.0 * M * K * N * reps / s / 1e9, C[0], K);
}
