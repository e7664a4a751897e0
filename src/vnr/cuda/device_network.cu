// A Network resident on the GPU: pass buffers, the half parameter upload, DeviceNetwork's batched
// forward pass and the GpuNetwork (batched inference and decoding) built on it.
#include <algorithm>
#include <cfloat>
#include <cmath>
#include <vector>
#include "vnr/core/rng.h"
#include "vnr/cuda/cuda.h"
#include "vnr/cuda/kernels.cuh"
#include "vnr/cuda/mlp.cuh"
#include "vnr/cuda/network.cuh"
#include "vnr/nn/optimizer.h"


namespace vnr::cuda {

void PassBuffers::allocate(const MlpDims& d, int64_t n, bool training, MlpPath path) {
  const int H = d.n_matrices - 1;
  X0.resize(size_t(n) * d.in_pad);
  out.resize(size_t(n) * d.n_out);
  if (training || path == MlpPath::Cublas) acts.resize(size_t(H) * n * d.width);
  if (path == MlpPath::Cublas) tmp.resize(size_t(n) * std::max(d.in_pad, d.width));
  if (training) {
    dOut.resize(size_t(n) * d.out_pad);
    dY.resize(size_t(H) * n * d.width);
    dX0.resize(size_t(n) * d.in_pad);
  }
}

void upload_half_params(const Network& net, DeviceBuffer<__half>& half) {
  std::vector<uint16_t> h = net.params_half();
  half.resize(h.size());
  VNR_CUDA_CHECK(cudaMemcpy(half.data(), h.data(), h.size() * sizeof(uint16_t), cudaMemcpyHostToDevice));
}

DeviceNetwork::DeviceNetwork(const Network& net, MlpPath asked) : net_(net) {
  check_supported(net);
  d_ = mlp_dims(net.mlp());
  path_ = resolve_mlp_path(net, asked);
  grid_kernels_ = grid_kernels(net.grid());
  upload_half_params(net, half_);
}

void DeviceNetwork::reload_params(const void* device_half) {
  VNR_CUDA_CHECK(cudaMemcpy(half_.data(), device_half, half_.size() * sizeof(__half), cudaMemcpyDeviceToDevice));
}

const float* DeviceNetwork::infer(const float* xyz, int64_t n, const StreamAndBlas& sb, cudaEvent_t after_encoding) {
  if (n > allocated_) {
    pass_.allocate(d_, n, false, path_);
    allocated_ = n;
  }
  grid_kernels_.encode(net_.grid(), half_.data() + net_.mlp().n_params, interleaved(xyz), n, d_.in_pad, pass_.X0.data(),
                       sb.stream);
  if (after_encoding) VNR_CUDA_CHECK(cudaEventRecord(after_encoding, sb.stream));
  mlp_forward(path_, d_, half_.data(), pass_.X0.data(), n, pass_.acts.data(), pass_.out.data(),
              int(net_.config().network.output_activation), pass_.tmp.data(), sb.blas, sb.stream);
  return pass_.out.data();
}

// ------------------------------------------------------------------------------------------------
// GpuNetwork

struct GpuNetwork::Impl {
  StreamAndBlas sb;  // first: fails with one line when there is no device
  DeviceNetwork dnet;
  DeviceBuffer<float> coords;
  std::vector<float> pad;
  int64_t slab = int64_t(1) << 22, allocated = 0;

  Impl(const Network& n, MlpPath asked) : dnet(n, asked) {}
  void ensure(int64_t n) {
    if (n <= allocated) return;
    coords.resize(size_t(n) * 3);
    allocated = n;
  }
  // Runs the padded points in `coords` [0, np) and copies the first m outputs to out.
  void run(int64_t m, int64_t np, float* out) {
    const cudaStream_t st = sb.stream;
    const float* res = dnet.infer(coords.data(), np, sb);
    const int n_out = dnet.dims().n_out;
    if (n_out == 1) {
      VNR_CUDA_CHECK(cudaMemcpyAsync(out, res, m * sizeof(float), cudaMemcpyDeviceToHost, st));
    } else {  // first output of each sample
      VNR_CUDA_CHECK(cudaMemcpy2DAsync(out, sizeof(float), res, n_out * sizeof(float), sizeof(float), size_t(m),
                                       cudaMemcpyDeviceToHost, st));
    }
    VNR_CUDA_CHECK(cudaStreamSynchronize(st));
  }
};

GpuNetwork::GpuNetwork(const Network& net, MlpPath mlp) : impl_(std::make_unique<Impl>(net, mlp)) {}
GpuNetwork::~GpuNetwork() = default;

void GpuNetwork::reload_params(const void* device_half) {
  VNR_CUDA_CHECK(cudaStreamSynchronize(impl_->sb.stream));  // no inference reads them while they change
  impl_->dnet.reload_params(device_half);
}

void GpuNetwork::infer(const float* coords, int64_t n, float* out) {
  Impl& I = *impl_;
  for (int64_t b = 0; b < n; b += I.slab) {
    const int64_t m = std::min(I.slab, n - b), np = round_up(m, 16);
    I.ensure(np);
    I.coords.upload(coords + 3 * b, size_t(3 * m));
    if (np > m) {  // pad with the last point (the fused kernels work on tiles of 16 samples)
      I.pad.resize(size_t(3 * (np - m)));
      for (int64_t i = 0; i < np - m; ++i)
        for (int k = 0; k < 3; ++k) I.pad[size_t(3 * i + k)] = coords[3 * (b + m - 1) + k];
      I.coords.upload(I.pad.data(), I.pad.size(), size_t(3 * m));
    }
    I.run(m, np, out + b);
  }
}

void GpuNetwork::decode_slices(Int3 dims, int64_t z0, int64_t z1, float* out) {
  Impl& I = *impl_;
  const int64_t first = dims.x * dims.y * z0, n = dims.x * dims.y * (z1 - z0);
  for (int64_t b = 0; b < n; b += I.slab) {
    const int64_t m = std::min(I.slab, n - b), np = round_up(m, 16);
    I.ensure(np);
    voxel_centres(dims, first + b, m, np, I.coords.data(), I.sb.stream);
    I.run(m, np, out + b);
  }
}

// At most 2^30 samples per slab: cuBLAS takes the sample count as an int.
void GpuNetwork::set_slab(int64_t samples) {
  impl_->slab = std::clamp<int64_t>(round_up(samples, 16), 16, int64_t(1) << 30);
}
MlpPath GpuNetwork::mlp_path() const { return impl_->dnet.path(); }
uint64_t GpuNetwork::peak_memory_bytes() const { return device_bytes_peak(); }

GpuNetwork::ResidentTiming GpuNetwork::time_resident(int64_t n, int repeats) {
  Impl& I = *impl_;
  const int64_t np = round_up(n, 16);
  I.ensure(np);
  std::vector<float> xyz(size_t(3 * np));
  Pcg32 rng(7);
  for (float& v : xyz) v = rng.next_float();
  I.coords.upload(xyz.data(), xyz.size());
  const cudaStream_t st = I.sb.stream;
  cudaEvent_t ev[3];
  for (cudaEvent_t& e : ev) VNR_CUDA_CHECK(cudaEventCreate(&e));
  double total = 0, mlp = 0;
  for (int r = -1; r < repeats; ++r) {  // r = -1: warm-up
    VNR_CUDA_CHECK(cudaEventRecord(ev[0], st));
    I.dnet.infer(I.coords.data(), np, I.sb, ev[1]);
    VNR_CUDA_CHECK(cudaEventRecord(ev[2], st));
    VNR_CUDA_CHECK(cudaEventSynchronize(ev[2]));
    float a = 0, b = 0;
    VNR_CUDA_CHECK(cudaEventElapsedTime(&a, ev[0], ev[2]));
    VNR_CUDA_CHECK(cudaEventElapsedTime(&b, ev[1], ev[2]));
    if (r >= 0) {
      total += a * 1e-3;
      mlp += b * 1e-3;
    }
  }
  for (cudaEvent_t e : ev) cudaEventDestroy(e);
  return ResidentTiming{total / std::max(1, repeats), mlp / std::max(1, repeats)};
}

}  // namespace vnr::cuda
