#pragma once
// One training step's loss-scaled gradient work on the GPU (CUDA-only header, shared by the GpuTrainer
// and the kernel-level test entry points).
#include "vnr/cuda/kernels.cuh"
#include "vnr/cuda/mlp.cuh"
#include "vnr/cuda/network.cuh"
#include "vnr/nn/network.h"

namespace vnr::cuda {

// Encoding, MLP forward, loss, MLP backward and grid backward for n points with their targets: the
// loss-scaled work of one training step (grads: binary32, the MLP part overwritten, the grid part
// accumulated), with the grid kernels gk of net's grid. mark(i) records the phase boundaries 1 (after
// encoding) and 2 (after the backward through the layers). Queued on sb.stream, ordered there.
template <typename Mark>
inline void gradient_pass(const Network& net, const GridKernels& gk, const MlpDims& d, MlpPath path, const __half* half,
                          Coords pts,
                   const float* target, int64_t n, PassBuffers& pass, float* grads, float* loss_slot,
                   const StreamAndBlas& sb, Mark&& mark) {
  const cudaStream_t st = sb.stream;
  const uint64_t n_mlp = net.mlp().n_params;
  const ModelConfig& cfg = net.config();
  gk.encode(net.grid(), half + n_mlp, pts, n, d.in_pad, pass.X0.data(), st);
  mark(1);
  mlp_forward(path, d, half, pass.X0.data(), n, pass.acts.data(), pass.out.data(), -1, pass.tmp.data(), sb.blas, st);
  loss_and_grad(cfg.loss, cfg.network.output_activation, pass.out.data(), target, n, d.n_out, d.out_pad,
                1.0f / float(n * d.n_out), pass.dOut.data(), loss_slot, st);
  mlp_backward_data(path, d, half, pass.acts.data(), pass.dOut.data(), n, pass.dY.data(), pass.dX0.data(),
                    pass.tmp.data(), sb.blas, st);
  mark(2);
  // The grid's backward (scattered atomics, bound by their latency: docs/benchmarks.md, CUDA backend) on
  // the side stream, beside the weight gradients' split-K GEMMs on the stream; disjoint reads and writes.
  sb.fork();
  try {
    gk.backward(net.grid(), pts, n, d.in_pad, pass.dX0.data(), grads + n_mlp, sb.side);
    mlp_weight_gradients(d, pass.X0.data(), pass.acts.data(), pass.dOut.data(), pass.dY.data(), n, grads, sb.blas, st);
  } catch (...) {
    sb.join();  // nothing queued later on the stream may race the side stream's work
    throw;
  }
  sb.join();
}

inline void no_mark(int) {}

}  // namespace vnr::cuda
