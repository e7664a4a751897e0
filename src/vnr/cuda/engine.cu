// Device query, the GPU trainer and the GPU network (host orchestration of kernels.cu and mlp.cu).
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

uint64_t& device_bytes_now() {
  static uint64_t b = 0;
  return b;
}
uint64_t& device_bytes_peak() {
  static uint64_t b = 0;
  return b;
}

bool built() { return true; }

std::vector<DeviceInfo> devices() {
  int n = 0;
  if (cudaGetDeviceCount(&n) != cudaSuccess) {
    cudaGetLastError();  // clear: no driver or no device is not an error of later calls
    return {};
  }
  std::vector<DeviceInfo> out;
  for (int i = 0; i < n; ++i) {
    cudaDeviceProp p;
    if (cudaGetDeviceProperties(&p, i) != cudaSuccess) continue;
    out.push_back(DeviceInfo{i, p.name, p.major, p.minor, uint64_t(p.totalGlobalMem), p.multiProcessorCount});
  }
  return out;
}

std::string no_device_reason() {
  int n = 0;
  cudaError_t e = cudaGetDeviceCount(&n);
  if (e != cudaSuccess) {
    cudaGetLastError();
    return std::string("no CUDA device (") + cudaGetErrorString(e) + ")";
  }
  return n == 0 ? "no CUDA device" : "";
}

uint64_t free_memory_bytes() {
  if (devices().empty()) return 0;
  size_t free_b = 0, total_b = 0;
  if (cudaMemGetInfo(&free_b, &total_b) != cudaSuccess) {
    cudaGetLastError();
    return 0;
  }
  return free_b;
}

void require_device() {
  if (devices().empty()) cuda_fail_message("--device cuda: " + no_device_reason());
}

StreamAndBlas::StreamAndBlas() {
  require_device();
  VNR_CUDA_CHECK(cudaStreamCreate(&stream));
  VNR_CUBLAS_CHECK(cublasCreate(&blas));
  VNR_CUBLAS_CHECK(cublasSetStream(blas, stream));
}
StreamAndBlas::~StreamAndBlas() {
  if (blas) cublasDestroy(blas);
  if (stream) cudaStreamDestroy(stream);
}

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
  upload_half_params(net, half_);
}

const float* DeviceNetwork::infer(const float* xyz, int64_t n, const StreamAndBlas& sb, cudaEvent_t after_encoding) {
  if (n > allocated_) {
    pass_.allocate(d_, n, false, path_);
    allocated_ = n;
  }
  encode(net_.grid(), half_.data() + net_.mlp().n_params, interleaved(xyz), n, d_.in_pad, pass_.X0.data(), sb.stream);
  if (after_encoding) VNR_CUDA_CHECK(cudaEventRecord(after_encoding, sb.stream));
  mlp_forward(path_, d_, half_.data(), pass_.X0.data(), n, pass_.acts.data(), pass_.out.data(),
              int(net_.config().network.output_activation), pass_.tmp.data(), sb.blas, sb.stream);
  return pass_.out.data();
}

namespace {

// Encoding, MLP forward, loss, MLP backward and grid backward for n points with their targets: the
// loss-scaled work of one training step (grads: binary32, the MLP part overwritten, the grid part
// accumulated). mark(i) records the phase boundaries 1 (after encoding) and 2 (after the MLP).
template <typename Mark>
void gradient_pass(const Network& net, const MlpDims& d, MlpPath path, const __half* half, Coords pts,
                   const float* target, int64_t n, PassBuffers& pass, float* grads, float* loss_slot,
                   const StreamAndBlas& sb, Mark&& mark) {
  const cudaStream_t st = sb.stream;
  const uint64_t n_mlp = net.mlp().n_params;
  const ModelConfig& cfg = net.config();
  encode(net.grid(), half + n_mlp, pts, n, d.in_pad, pass.X0.data(), st);
  mark(1);
  mlp_forward(path, d, half, pass.X0.data(), n, pass.acts.data(), pass.out.data(), -1, pass.tmp.data(), sb.blas, st);
  loss_and_grad(cfg.loss, cfg.network.output_activation, pass.out.data(), target, n, d.n_out, d.out_pad,
                1.0f / float(n * d.n_out), pass.dOut.data(), loss_slot, st);
  mlp_backward(path, d, half, pass.X0.data(), pass.acts.data(), pass.dOut.data(), n, pass.dY.data(), pass.dX0.data(),
               grads, pass.tmp.data(), sb.blas, st);
  mark(2);
  grid_backward(net.grid(), pts, n, d.in_pad, pass.dX0.data(), grads + n_mlp, st);
}

inline void no_mark(int) {}

}  // namespace

// ------------------------------------------------------------------------------------------------
// GpuTrainer

struct GpuTrainer::Impl {
  Network& net;
  GpuTrainOptions opts;
  MlpDims d;
  MlpPath path;
  StreamAndBlas sb;
  DeviceBuffer<float> volume;
  GridView dvol;
  DeviceBuffer<float> master, grads, m, v;
  DeviceBuffer<uint32_t> c;
  DeviceBuffer<__half> half;
  DeviceBuffer<float> xs, ys, zs, target;
  PassBuffers pass;
  DeviceBuffer<float> loss_slots, bias_sqrt, bias_den;
  std::vector<float> h_bias_sqrt, h_bias_den;
  uint64_t step = 0;
  float factor = 1.0f;  // ExponentialDecay's
  bool profiling = false;
  cudaEvent_t events[5] = {};
  ValueRangeGrid ranges;  // shape of the online ranges (their values live in range_lo/hi; none: off)
  DeviceBuffer<float> range_lo, range_hi;

  Impl(Network& n, GridView vol, GpuTrainOptions o) : net(n), opts(o) {
    check_supported(net);
    if (opts.batch <= 0 || opts.batch % kChunk != 0)
      cuda_fail_message("batch size must be a positive multiple of " + std::to_string(kChunk) + ", got " +
                        std::to_string(opts.batch));
    if (opts.chunk <= 0 || opts.batch % opts.chunk != 0) cuda_fail_message("the sampling chunk must divide the batch");
    d = mlp_dims(net.mlp());
    path = resolve_mlp_path(net, opts.mlp);
    const uint64_t voxels = uint64_t(vol.nx) * vol.ny * vol.nz;
    const uint64_t need = GpuTrainer::bytes_needed(net, voxels, opts.batch), free_b = free_memory_bytes();
    if (need > free_b)
      cuda_fail_message("training this volume on the GPU needs about " + std::to_string(need >> 20) + " MiB, " +
                        std::to_string(free_b >> 20) + " MiB are free: use --device cpu");
    volume.resize(voxels);
    volume.upload(vol.data, voxels);
    dvol = GridView{volume.data(), vol.nx, vol.ny, vol.nz};
    const uint64_t P = net.n_params();
    master.resize(P);
    master.upload(net.params.data(), P);
    for (DeviceBuffer<float>* b : {&grads, &m, &v}) {
      b->resize(P);
      b->zero_async(sb.stream);
    }
    c.resize(P);
    c.zero_async(sb.stream);
    upload_half_params(net, half);
    const int64_t B = opts.batch;
    xs.resize(B);
    ys.resize(B);
    zs.resize(B);
    target.resize(B);
    pass.allocate(d, B, true, path);
    grow_tables(1 << 14);
    VNR_CUDA_CHECK(cudaStreamSynchronize(sb.stream));
  }

  // Bias corrections by per-parameter step count (the CPU Adam's tables, same host arithmetic) and one
  // loss slot per step; grown by doubling, the only synchronising copies of a run.
  void grow_tables(uint64_t need) {
    if (need <= h_bias_sqrt.size()) return;
    const uint64_t cap = std::max<uint64_t>(need, 2 * h_bias_sqrt.size());
    extend_adam_bias_tables(net.config().adam, cap, h_bias_sqrt, h_bias_den);
    VNR_CUDA_CHECK(cudaStreamSynchronize(sb.stream));
    bias_sqrt.resize(cap);
    bias_den.resize(cap);
    bias_sqrt.upload(h_bias_sqrt.data(), cap);
    bias_den.upload(h_bias_den.data(), cap);
    DeviceBuffer<float> slots(cap);
    VNR_CUDA_CHECK(cudaMemset(slots.data(), 0, cap * sizeof(float)));
    if (loss_slots.size())
      VNR_CUDA_CHECK(cudaMemcpy(slots.data(), loss_slots.data(), loss_slots.size() * sizeof(float),
                                cudaMemcpyDeviceToDevice));
    loss_slots = std::move(slots);
  }

  ~Impl() {
    for (cudaEvent_t e : events)
      if (e) cudaEventDestroy(e);
  }
  void mark(int i) {
    if (profiling) VNR_CUDA_CHECK(cudaEventRecord(events[i], sb.stream));
  }

  void one_step() {
    const cudaStream_t st = sb.stream;
    mark(0);
    const AdamConfig& a = net.config().adam;
    const AdamStepScalars sc = adam_step_scalars(a, net.config().decay, step, &factor);
    grow_tables(step + 2);
    sample_in_core(dvol, opts.seed, step, opts.chunk, opts.batch, xs.data(), ys.data(), zs.data(), target.data(), st);
    if (range_lo.size())
      ranges_add_samples(range_grid_dims(ranges), xs.data(), ys.data(), zs.data(), target.data(), opts.batch, range_lo.data(),
                         range_hi.data(), st);
    gradient_pass(net, d, path, half.data(), Coords{xs.data(), ys.data(), zs.data(), 1}, target.data(), opts.batch,
                  pass, grads.data(), loss_slots.data() + step, sb, [&](int i) { mark(i); });
    mark(3);
    ++step;
    AdamArgs args{sc.lr, a.beta1, a.beta2, a.epsilon, a.l2_reg, a.relative_decay, a.absolute_decay, sc.lo, sc.hi, 1};
    const uint64_t n_mlp = net.mlp().n_params;
    const uint64_t P = net.n_params();
    if (a.optimize_matrix_params)
      adam(args, master.data(), grads.data(), m.data(), v.data(), c.data(), half.data(), int64_t(n_mlp),
           bias_sqrt.data(), bias_den.data(), st);
    else
      VNR_CUDA_CHECK(cudaMemsetAsync(grads.data(), 0, n_mlp * sizeof(float), st));
    args.matrix = 0;
    args.lr *= a.non_matrix_learning_rate_factor;
    if (a.optimize_non_matrix_params)
      adam(args, master.data() + n_mlp, grads.data() + n_mlp, m.data() + n_mlp, v.data() + n_mlp, c.data() + n_mlp,
           half.data() + n_mlp, int64_t(P - n_mlp), bias_sqrt.data(), bias_den.data(), st);
    else
      VNR_CUDA_CHECK(cudaMemsetAsync(grads.data() + n_mlp, 0, (P - n_mlp) * sizeof(float), st));
    mark(4);
  }
};

GpuTrainer::GpuTrainer(Network& net, GridView volume, GpuTrainOptions opts)
    : impl_(std::make_unique<Impl>(net, volume, opts)) {}
GpuTrainer::~GpuTrainer() = default;

void GpuTrainer::run(int n_steps) {
  for (int i = 0; i < n_steps; ++i) impl_->one_step();
}
void GpuTrainer::synchronize() { VNR_CUDA_CHECK(cudaStreamSynchronize(impl_->sb.stream)); }

std::vector<float> GpuTrainer::losses() {
  synchronize();
  std::vector<float> out(impl_->step);
  if (!out.empty()) impl_->loss_slots.download(out.data(), out.size());
  return out;
}
uint64_t GpuTrainer::steps_done() const { return impl_->step; }
float GpuTrainer::last_loss() {
  if (impl_->step == 0) return 0.0f;
  synchronize();
  float l = 0;
  impl_->loss_slots.download(&l, 1, impl_->step - 1);
  return l;
}
float GpuTrainer::current_learning_rate() const {
  return impl_->net.config().adam.learning_rate * impl_->factor;
}

void GpuTrainer::enable_online_ranges(Int3 dims, int cell_size) {
  Impl& I = *impl_;
  I.ranges = ValueRangeGrid(dims, cell_size);
  I.range_lo.resize(size_t(I.ranges.count()));
  I.range_hi.resize(size_t(I.ranges.count()));
  ranges_clear(range_grid_dims(I.ranges), I.range_lo.data(), I.range_hi.data(), I.sb.stream);
}
bool GpuTrainer::has_online_ranges() const { return impl_->range_lo.size() > 0; }
ValueRangeGrid GpuTrainer::online_ranges() {
  Impl& I = *impl_;
  if (!has_online_ranges()) cuda_fail_message("online macro-cells were not enabled for this training run");
  synchronize();
  ValueRangeGrid g = I.ranges;
  I.range_lo.download(g.lo.data(), g.lo.size());
  I.range_hi.download(g.hi.data(), g.hi.size());
  return g;
}

void GpuTrainer::download() {
  synchronize();
  impl_->master.download(impl_->net.params.data(), impl_->net.n_params());
  impl_->net.sync_half_table();
}
MlpPath GpuTrainer::mlp_path() const { return impl_->path; }
uint64_t GpuTrainer::peak_memory_bytes() const { return device_bytes_peak(); }

void GpuTrainer::set_profiling(bool on) {
  if (on && !impl_->events[0])
    for (cudaEvent_t& e : impl_->events) VNR_CUDA_CHECK(cudaEventCreate(&e));
  impl_->profiling = on;
}

std::vector<double> GpuTrainer::phase_seconds() {
  if (!impl_->profiling || impl_->step == 0) return {};
  synchronize();
  std::vector<double> out;
  for (int i = 0; i < 4; ++i) {
    float ms = 0;
    VNR_CUDA_CHECK(cudaEventElapsedTime(&ms, impl_->events[i], impl_->events[i + 1]));
    out.push_back(ms * 1e-3);
  }
  return out;
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
  vnr::cuda::encode(net.grid(), half.data() + net.mlp().n_params, interleaved(pts.data()), n, d.in_pad, X0.data(),
                    sb.stream);
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
  gradient_pass(net, d, path, half.data(), interleaved(pts.data()), tgt.data(), n, pass, grads.data(), slot.data(), sb,
                no_mark);
  VNR_CUDA_CHECK(cudaStreamSynchronize(st));
  std::vector<float> out(net.n_params());
  grads.download(out.data(), out.size());
  if (loss) slot.download(loss, 1);
  return out;
}

}  // namespace testing
}  // namespace vnr::cuda
