// The GpuTrainer: sampling, the gradient pass and Adam on the GPU, steps queued on one stream.
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
#include "vnr/core/parallel.h"
#include "vnr/nn/optimizer.h"
#include "vnr/nn/quantization_hd.h"


namespace vnr::cuda {
namespace {

// Quantization-aware steps: what each step's forward pass reads is the stored value of its master.
struct WriteQuantizedHalf {
  const float* master;
  const float* step;  // per parameter
  __half* half;
  __device__ void operator()(int64_t i) const { half[i] = __float2half_rn(quantized_value(master[i], step[i])); }
};
struct WriteHalf {
  const float* master;
  __half* half;
  __device__ void operator()(int64_t i) const { half[i] = __float2half_rn(master[i]); }
};

// *sum += sum of |w[i]| over [0, n): a block's partial sums, then one atomic add per block.
constexpr int kSumThreads = 256;
__global__ void abs_sum_kernel(const float* __restrict__ w, int64_t n, double* sum) {
  __shared__ double part[kSumThreads];
  double local = 0;
  for (int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x; i < n; i += int64_t(gridDim.x) * blockDim.x)
    local += fabs(double(w[i]));
  part[threadIdx.x] = local;
  __syncthreads();
  for (int k = kSumThreads / 2; k > 0; k >>= 1) {
    if (int(threadIdx.x) < k) part[threadIdx.x] += part[threadIdx.x + k];
    __syncthreads();
  }
  if (threadIdx.x == 0) atomicAdd(sum, part[0]);
}

// One segment's rate-term gradient, per parameter as train/rate_term.cpp's add_rate_gradient adds it.
struct AddRateGradient {
  const float* master;
  float* grads;
  const double* abs_sum;  // the segment's sum of |master|
  const float* loss;      // the previous step's
  double weight_per_loss;
  uint64_t count;
  float step;
  __device__ void operator()(int64_t i) const {
    double d;
    laplace_bin_bits(master[i], step, laplace_scale(*abs_sum, count, step), &d);
    grads[i] += float(weight_per_loss * double(*loss) * d);
  }
};

}  // namespace

// ------------------------------------------------------------------------------------------------
// GpuTrainer

struct GpuTrainer::Impl {
  Network& net;
  GpuTrainOptions opts;
  MlpDims d;
  MlpPath path;
  GridKernels grid_kernels;  // for the grid's features per level, chosen once
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
  float factor = 1.0f;   // ExponentialDecay's
  float lr_mult = 1.0f;  // set_learning_rate_multiplier's
  bool profiling = false;
  cudaEvent_t events[5] = {};
  ValueRangeGrid ranges;  // shape of the online ranges (their values live in range_lo/hi; none: off)
  DeviceBuffer<float> range_lo, range_hi;
  // Host-drawn batches: two pinned staging buffers of x|y|z|target, each free again once its copy
  // (recorded by its event) is done.
  std::shared_ptr<HostBatchSource> source;
  float* staging[2] = {};
  cudaEvent_t staged[2] = {};
  // Quantization-aware steps (begin_quantized): each parameter's step (empty: off) and the segments
  // the rate term covers, with their sums of |master|.
  struct RateSegment {
    uint64_t begin, count;
    float step;
  };
  DeviceBuffer<float> quant_step;
  std::vector<RateSegment> rate_segments;
  DeviceBuffer<double> rate_abs_sum;
  double rate_weight_per_loss = 0;

  Impl(Network& n, GridView vol, GpuTrainOptions o) : net(n), opts(o) {
    check_options();
    const uint64_t voxels = uint64_t(vol.nx) * vol.ny * vol.nz;
    allocate(voxels);
    volume.resize(voxels);
    volume.upload(vol.data, voxels);
    dvol = GridView{volume.data(), vol.nx, vol.ny, vol.nz};
    VNR_CUDA_CHECK(cudaStreamSynchronize(sb.stream));
  }

  Impl(Network& n, std::shared_ptr<HostBatchSource> src, GpuTrainOptions o) : net(n), opts(o), source(std::move(src)) {
    if (!source) cuda_fail_message("the GPU trainer needs a volume or a source of batches");
    check_options();
    allocate(0);
    for (int k = 0; k < 2; ++k) {
      VNR_CUDA_CHECK(cudaMallocHost(&staging[k], size_t(4 * opts.batch) * sizeof(float)));
      VNR_CUDA_CHECK(cudaEventCreateWithFlags(&staged[k], cudaEventDisableTiming));
    }
    VNR_CUDA_CHECK(cudaStreamSynchronize(sb.stream));
  }

  void check_options() {
    check_supported(net);
    if (opts.batch <= 0 || opts.batch % kChunk != 0)
      cuda_fail_message("batch size must be a positive multiple of " + std::to_string(kChunk) + ", got " +
                        std::to_string(opts.batch));
    if (opts.chunk <= 0 || opts.batch % opts.chunk != 0) cuda_fail_message("the sampling chunk must divide the batch");
    d = mlp_dims(net.mlp());
    path = resolve_mlp_path(net, opts.mlp);
    grid_kernels = cuda::grid_kernels(net.grid());
  }

  // The optimizer state and a step's buffers, after checking that they and `voxels` fit.
  void allocate(uint64_t voxels) {
    const uint64_t need = GpuTrainer::bytes_needed(net, voxels, opts.batch), free_b = free_memory_bytes();
    if (need > free_b)
      cuda_fail_message("training this volume on the GPU needs about " + std::to_string(need >> 20) + " MiB, " +
                        std::to_string(free_b >> 20) + " MiB are free: use --device cpu");
    const uint64_t P = net.n_params();
    master.resize(P);
    master.upload(net.params().data(), P);
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
    cudaStreamSynchronize(sb.stream);  // no copy may still read a staging buffer
    for (cudaEvent_t e : events)
      if (e) cudaEventDestroy(e);
    for (int k = 0; k < 2; ++k) {
      if (staged[k]) cudaEventDestroy(staged[k]);
      if (staging[k]) cudaFreeHost(staging[k]);
    }
  }

  // This step's samples: drawn on the GPU from the resident volume, or on the host and copied.
  void draw_samples(cudaStream_t st) {
    if (!source) {
      sample_in_core(dvol, opts.seed, step, opts.chunk, opts.batch, xs.data(), ys.data(), zs.data(), target.data(), st);
      return;
    }
    const int k = int(step % 2);
    VNR_CUDA_CHECK(cudaEventSynchronize(staged[k]));  // the copy of step - 2 from this buffer is done
    const int64_t B = opts.batch;
    float* h = staging[k];
    source->fill(step, B, h, h + B, h + 2 * B, h + 3 * B);
    DeviceBuffer<float>* dst[4] = {&xs, &ys, &zs, &target};
    for (int j = 0; j < 4; ++j)
      VNR_CUDA_CHECK(cudaMemcpyAsync(dst[j]->data(), h + j * B, size_t(B) * sizeof(float), cudaMemcpyHostToDevice, st));
    VNR_CUDA_CHECK(cudaEventRecord(staged[k], st));
  }
  void mark(int i) {
    if (profiling) VNR_CUDA_CHECK(cudaEventRecord(events[i], sb.stream));
  }

  void one_step() {
    const cudaStream_t st = sb.stream;
    mark(0);
    const AdamConfig& a = net.config().adam;
    AdamStepScalars sc = adam_step_scalars(a, net.config().decay, step, &factor);
    sc.lr *= lr_mult;
    grow_tables(step + 2);
    draw_samples(st);
    if (range_lo.size())
      ranges_add_samples(range_grid_dims(ranges), xs.data(), ys.data(), zs.data(), target.data(), opts.batch, range_lo.data(),
                         range_hi.data(), st);
    gradient_pass(net, grid_kernels, d, path, half.data(), Coords{xs.data(), ys.data(), zs.data(), 1}, target.data(), opts.batch,
                  pass, grads.data(), loss_slots.data() + step, sb, [&](int i) { mark(i); });
    mark(3);
    if (!rate_segments.empty()) add_rate_gradients(st);
    ++step;
    AdamArgs args{{sc.lr, a.beta1, a.beta2, a.epsilon, a.l2_reg, a.relative_decay, a.absolute_decay, sc.lo, sc.hi}, 1};
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
    if (quant_step.size()) {  // the next step reads the quantized values (Adam wrote their fp16)
      parallel_for(st, int64_t(P), WriteQuantizedHalf{master.data(), quant_step.data(), half.data()});
      VNR_CUDA_LAUNCHED();
    }
    mark(4);
  }

  void add_rate_gradients(cudaStream_t st) {
    const float* loss = loss_slots.data() + (step > 0 ? step - 1 : 0);
    VNR_CUDA_CHECK(cudaMemsetAsync(rate_abs_sum.data(), 0, rate_abs_sum.size() * sizeof(double), st));
    for (size_t k = 0; k < rate_segments.size(); ++k) {
      const RateSegment& r = rate_segments[k];
      const unsigned blocks = std::min(blocks_for(int64_t(r.count), kSumThreads), 1024u);
      abs_sum_kernel<<<blocks, kSumThreads, 0, st>>>(master.data() + r.begin, int64_t(r.count), rate_abs_sum.data() + k);
      VNR_CUDA_LAUNCHED();
      parallel_for(st, int64_t(r.count),
                   AddRateGradient{master.data() + r.begin, grads.data() + r.begin, rate_abs_sum.data() + k, loss,
                                   rate_weight_per_loss, r.count, r.step});
      VNR_CUDA_LAUNCHED();
    }
  }
};

GpuTrainer::GpuTrainer(Network& net, GridView volume, GpuTrainOptions opts)
    : impl_(std::make_unique<Impl>(net, volume, opts)) {}
GpuTrainer::GpuTrainer(Network& net, std::shared_ptr<HostBatchSource> source, GpuTrainOptions opts)
    : impl_(std::make_unique<Impl>(net, std::move(source), opts)) {}
GpuTrainer::~GpuTrainer() = default;

void GpuTrainer::run(int n_steps) {
  for (int i = 0; i < n_steps; ++i) impl_->one_step();
}
void GpuTrainer::synchronize() { VNR_CUDA_CHECK(cudaStreamSynchronize(impl_->sb.stream)); }

std::vector<float> GpuTrainer::losses(uint64_t first) {
  synchronize();
  first = std::min<uint64_t>(first, impl_->step);
  std::vector<float> out(impl_->step - first);
  if (!out.empty()) impl_->loss_slots.download(out.data(), out.size(), first);
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
  return impl_->net.config().adam.learning_rate * impl_->factor * impl_->lr_mult;
}
void GpuTrainer::set_learning_rate_multiplier(float m) { impl_->lr_mult = m; }

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
  impl_->net.edit_params([&](float* p, size_t n) { impl_->master.download(p, n); });
}
const void* GpuTrainer::device_half_params() {
  synchronize();
  return impl_->half.data();
}
void GpuTrainer::begin_quantized(const std::vector<float>& master, const std::vector<ParamSegment>& segments,
                                 size_t first_rate_segment, double rate_weight_per_loss) {
  Impl& I = *impl_;
  const uint64_t P = I.net.n_params();
  if (master.size() != P)
    cuda_fail_message("quantized steps: a master copy of " + std::to_string(master.size()) + " parameters for a network of " +
                      std::to_string(P));
  std::vector<float> steps(P);
  std::vector<Impl::RateSegment> rate;
  uint64_t off = 0;
  for (size_t k = 0; k < segments.size(); ++k) {
    const ParamSegment& s = segments[k];
    if (s.count > P - off) cuda_fail_message("quantized steps: the segments cover more than the network's parameters");
    std::fill(steps.begin() + int64_t(off), steps.begin() + int64_t(off + s.count), s.step);
    if (rate_weight_per_loss > 0 && k >= first_rate_segment && s.step > 0 && s.count > 0)
      rate.push_back(Impl::RateSegment{off, s.count, s.step});
    off += s.count;
  }
  if (off != P) cuda_fail_message("quantized steps: the segments cover " + std::to_string(off) + " of " + std::to_string(P) + " parameters");
  synchronize();  // no queued step may still read the master copy
  I.master.upload(master.data(), P);
  I.quant_step.resize(P);
  I.quant_step.upload(steps.data(), P);
  I.rate_segments = std::move(rate);
  I.rate_abs_sum.resize(std::max<size_t>(1, I.rate_segments.size()));
  I.rate_weight_per_loss = rate_weight_per_loss;
  parallel_for(I.sb.stream, int64_t(P), WriteQuantizedHalf{I.master.data(), I.quant_step.data(), I.half.data()});
  VNR_CUDA_LAUNCHED();
}

void GpuTrainer::end_quantized(std::vector<float>& master) {
  Impl& I = *impl_;
  const uint64_t P = I.net.n_params();
  synchronize();
  master.resize(P);
  I.master.download(master.data(), P);
  I.quant_step = DeviceBuffer<float>();
  I.rate_segments.clear();
  parallel_for(I.sb.stream, int64_t(P), WriteHalf{I.master.data(), I.half.data()});
  VNR_CUDA_LAUNCHED();
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

}  // namespace vnr::cuda
