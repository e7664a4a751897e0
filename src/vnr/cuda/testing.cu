// Kernel-level entry points for the GPU tests (cuda::testing in cuda.h).
#include <algorithm>
#include <cfloat>
#include <cmath>
#include <vector>
#include "vnr/core/rng.h"
#include "vnr/cuda/cuda.h"
#include "vnr/cuda/kernels.cuh"
#include "vnr/cuda/mlp.cuh"
#include "vnr/cuda/gradient_pass.cuh"
#include "vnr/cuda/network.cuh"
#include "vnr/nn/optimizer.h"


namespace vnr::cuda {

// ------------------------------------------------------------------------------------------------
// Kernel-level entry points for the gpu tests

namespace testing {

std::vector<float> encode(const Network& net, const float* coords, int n) {
  check_supported(net);
  StreamAndBlas sb;
  const MlpDims d = mlp_dims(net.mlp());
  DeviceBuffer<__half> half, X0(size_t(n) * d.in_pad);
  upload_half_params(net, half);
  DeviceBuffer<float> pts(size_t(3) * n);
  pts.upload(coords, size_t(3) * n);
  grid_kernels(net.grid()).encode(net.grid(), half.data() + net.mlp().n_params, interleaved(pts.data()), n, d.in_pad,
                                  X0.data(), sb.stream);
  std::vector<__half> h(X0.size());
  VNR_CUDA_CHECK(cudaStreamSynchronize(sb.stream));
  X0.download(h.data(), h.size());
  std::vector<float> out(h.size());
  for (size_t i = 0; i < h.size(); ++i) out[i] = __half2float(h[i]);
  return out;
}

std::vector<float> gradient(const Network& net, const float* coords, const float* targets, int n, MlpPath mlp,
                            float* loss) {
  check_supported(net);
  if (n % 16) cuda_fail_message("testing::gradient: n must be a multiple of 16");
  StreamAndBlas sb;
  const cudaStream_t st = sb.stream;
  const MlpDims d = mlp_dims(net.mlp());
  const MlpPath path = resolve_mlp_path(net, mlp);
  DeviceBuffer<__half> half;
  upload_half_params(net, half);
  DeviceBuffer<float> pts(size_t(3) * n), tgt(n), grads(net.n_params()), slot(1);
  pts.upload(coords, size_t(3) * n);
  tgt.upload(targets, n);
  grads.zero_async(st);
  slot.zero_async(st);
  PassBuffers pass;
  pass.allocate(d, n, true, path);
  gradient_pass(net, grid_kernels(net.grid()), d, path, half.data(), interleaved(pts.data()), tgt.data(), n, pass, grads.data(), slot.data(), sb,
                no_mark);
  VNR_CUDA_CHECK(cudaStreamSynchronize(st));
  std::vector<float> out(net.n_params());
  grads.download(out.data(), out.size());
  if (loss) slot.download(loss, 1);
  return out;
}

}  // namespace testing

}  // namespace vnr::cuda
