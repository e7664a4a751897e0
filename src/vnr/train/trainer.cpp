#include "vnr/train/trainer.h"
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstring>
#include "vnr/error.h"
#include "vnr/core/parallel.h"
#include "vnr/units.h"
#include "vnr/nn/loss.h"
#include "vnr/nn/mlp_bf16.h"

namespace vnr {

namespace {

// loss_value_and_grad() over n outputs with the loss type fixed at compile time (the per-sample switch
// folds away): dout = dL/d(pre-activation), and the summed loss in 8 interleaved double partial sums
// (independent chains; a fixed order, so still deterministic).
template <LossType kLoss>
double loss_and_grads_of(Activation act, const float* out, const float* pre, const float* target, int n, float inv_n,
                         float* dout) {
  double part[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  for (int s = 0; s < n; ++s) {
    float g;
    part[s & 7] += loss_value_and_grad(kLoss, out[s], target[s], inv_n, &g);
    dout[s] = act == Activation::None ? g : g * activate_derivative(act, pre[s]);
  }
  return ((part[0] + part[1]) + (part[2] + part[3])) + ((part[4] + part[5]) + (part[6] + part[7]));
}

double loss_and_grads(LossType loss, Activation act, const float* out, const float* pre, const float* target, int n,
                      float inv_n, float* dout) {
  switch (loss) {
    case LossType::L1: return loss_and_grads_of<LossType::L1>(act, out, pre, target, n, inv_n, dout);
    case LossType::L2: return loss_and_grads_of<LossType::L2>(act, out, pre, target, n, inv_n, dout);
    case LossType::RelativeL2: return loss_and_grads_of<LossType::RelativeL2>(act, out, pre, target, n, inv_n, dout);
    case LossType::RelativeL1: return loss_and_grads_of<LossType::RelativeL1>(act, out, pre, target, n, inv_n, dout);
  }
  fail("unknown loss type");
}

// The network's parameters fit (Network checks them); training adds, per parameter, Adam's two moments
// and step count and the gradient (16 bytes), plus each thread's MLP gradient. Refuse what cannot fit
// before the first of those vectors is allocated, naming the sizes. Returns n_params for Adam.
uint64_t checked_training_params(const Network& net) {
  const double bytes =
      double(net.n_params()) * (3 * sizeof(float) + sizeof(uint32_t)) + double(num_threads()) * net.mlp().n_params * 4;
  const uint64_t available = available_memory_bytes();
  if (bytes <= double(available))
    return net.n_params();
  fail("training the model's {} parameters needs {} more (gradients, Adam's moments and step counts), exceeding the "
       "memory available ({}); reduce n_levels, log2_hashmap_size or the grid resolution",
       net.n_params(), human_bytes(bytes), human_bytes(double(available)));
}

}  // namespace

Precision resolve_training_precision(const std::string& name, const Network& net) {
  if (name == "fp32") return Precision::FP32;
  // auto trains in fp32: bf16 MLP training cost 0.12-0.21 dB on chris_t1 at equal seeds
  // (docs/benchmarks.md "bf16 against fp32 training"); bf16 stays available on request.
  if (name == "auto") return Precision::FP32;
  if (name != "bf16") fail("unknown precision '{}' (allowed: auto, fp32, bf16)", name);
  if (!kernels::bf16_supported()) fail("precision bf16 needs a CPU with AVX512-BF16 (this one has none); use fp32");
  if (!net.bf16_training_supported())
    fail("bf16 training needs a ReLU MLP of width 16, 32, 64 or 128 with at most 128 inputs and outputs; use fp32");
  return Precision::BF16;
}

CpuTrainer::CpuTrainer(Network& net, std::shared_ptr<Sampler> sampler, TrainOptions opts)
    : net_(net), sampler_(std::move(sampler)), opts_(opts),
      adam_(net.config().adam, net.config().decay, checked_training_params(net), net.mlp().n_params) {
  if (opts_.batch <= 0 || opts_.batch % kChunk != 0)
    fail("batch size must be a positive multiple of {}, got {}", kChunk, opts_.batch);
  n_threads_ = num_threads();
  const MlpLayout& m = net.mlp();
  grads_.assign(net.n_params(), 0.0f);
  private_grid_grads_ =
      net.has_grid() && (net.n_params() - m.n_params) * sizeof(float) <= opts_.private_grid_grad_max_bytes;
  dW_.assign(n_threads_, std::vector<float>(private_grid_grads_ ? net.n_params() : m.n_params, 0.0f));
  // Every chunk full (the batch is a multiple of kChunk): the encoding-gradient rows all have one stride.
  const int C = kChunk;
  // workspace per thread: target, X0, acts, out_pre, out, dout, scratch, dEnc (acts and scratch: fp32
  // MLP only, the bf16 MLP keeps its activations in bf16_ws_; dEnc: private grid gradients only)
  const bool fp32_mlp = opts_.precision != Precision::BF16;
  size_t ws = C + size_t(m.in_pad) * C + (fp32_mlp ? net.acts_floats(C) : 0) + 3 * size_t(m.n_out) * C +
              (fp32_mlp ? 2 * size_t(m.width) * C : 0) + (private_grid_grads_ ? size_t(m.in_pad) * C : 0);
  ws_.assign(n_threads_, std::vector<float>(ws, 0.0f));
  if (opts_.precision == Precision::BF16) {
    resolve_training_precision("bf16", net);  // its checks: one error line where bf16 cannot run
    bf16_ws_.assign(n_threads_, std::vector<uint32_t>(net.mlp_train_bf16_scratch(C)));
  }
  xs_.resize(opts_.batch);
  ys_.resize(opts_.batch);
  zs_.resize(opts_.batch);
  const int64_t n_chunks = opts_.batch / C;
  if (net.has_grid() && !private_grid_grads_) dEnc_.resize(size_t(n_chunks) * C * m.in_pad);
  chunk_loss_.resize(n_chunks);
  n_tail_ = n_threads_ > 1 ? std::clamp<int64_t>(opts_.shared_tail_chunks, 0, n_chunks / 2) : 0;
  tail_dW_.assign(size_t(n_tail_) * m.n_params, 0.0f);
  if (private_grid_grads_) tail_dEnc_.resize(size_t(n_tail_) * C * m.in_pad);
}

float CpuTrainer::step() {
  const MlpLayout& m = net_.mlp();
  const int64_t C = kChunk;
  const int64_t n_chunks = opts_.batch / C;
  const uint64_t step = adam_.steps_done();
  const float inv_n = 1.0f / float(opts_.batch * m.n_out);
  const bool grid = net_.has_grid();
  sampler_->begin_step(step);
  auto t0 = std::chrono::steady_clock::now();
  const bool bf16 = opts_.precision == Precision::BF16;
  if (bf16) bf16_w_ = net_.bf16_train_weights();  // the weights changed in the last step's Adam

  const int64_t n_static = n_chunks - n_tail_;
  std::atomic<int64_t> next_tail{0};
  parallel_threads([&](int t, int nt) {
    std::vector<float>& w = ws_[t];
    float* target = w.data();
    float* X0 = target + C;
    float* acts = X0 + size_t(m.in_pad) * C;
    float* out_pre = acts + (bf16 ? 0 : net_.acts_floats(int(C)));
    float* out = out_pre + size_t(m.n_out) * C;
    float* dout = out + size_t(m.n_out) * C;
    float* scratch = dout + size_t(m.n_out) * C;
    float* chunk_dEnc = scratch + (bf16 ? 0 : 2 * size_t(m.width) * C);
    // One chunk: MLP gradient accumulated into dW; dL/dX0 (when there is a grid) into the batch buffer,
    // or for a private grid into private_dEnc, and then scattered into grid_dW when that is not null.
    auto run_chunk = [&](int64_t c, float* dW, float* private_dEnc, float* grid_dW) {
      float* dEnc = !grid ? nullptr : private_grid_grads_ ? private_dEnc : dEnc_.data() + c * int64_t(m.in_pad) * C;
      float* x = xs_.data() + c * C;
      float* y = ys_.data() + c * C;
      float* z = zs_.data() + c * C;
      const int n = int(C);
      sampler_->sample(opts_.seed, step, uint64_t(c), n, x, y, z, target);
      if (!thread_ranges_.empty()) thread_ranges_[t].add_samples(x, y, z, target, n);
      net_.encode(x, y, z, n, X0);
      if (bf16) net_.mlp_forward_train_bf16(X0, n, bf16_w_, bf16_ws_[t].data(), out_pre, out);
      else net_.mlp_forward(X0, n, acts, out_pre, out);
      double loss = 0;
      for (uint32_t o = 0; o < m.n_out; ++o)  // n_out targets per sample; vnr volumes are scalar (n_out = 1)
        loss += loss_and_grads(net_.config().loss, m.output_activation, out + o * n, out_pre + o * n, target, n,
                               inv_n, dout + o * n);
      chunk_loss_[c] = loss;
      if (bf16) net_.mlp_backward_train_bf16(dout, n, bf16_w_, bf16_ws_[t].data(), dW, dEnc);
      else net_.mlp_backward(X0, acts, dout, n, dW, dEnc, scratch);
      if (grid_dW)
        for (uint32_t l = 0; l < net_.grid().n_levels; ++l) net_.grid_backward_level(l, x, y, z, n, dEnc, n, grid_dW);
    };
    float* dW = dW_[t].data();
    std::memset(dW, 0, sizeof(float) * dW_[t].size());
    for (int64_t c = t; c < n_static; c += nt)
      run_chunk(c, dW, chunk_dEnc, private_grid_grads_ ? dW + m.n_params : nullptr);
    // The shared tail: claimed in any order, but each chunk's results go to its own slots.
    for_each_claimed(next_tail, n_tail_, [&](int64_t i) {
      float* tdW = tail_dW_.data() + i * int64_t(m.n_params);
      std::memset(tdW, 0, sizeof(float) * m.n_params);
      run_chunk(n_static + i, tdW, private_grid_grads_ ? tail_dEnc_.data() + i * int64_t(m.in_pad) * C : nullptr,
                nullptr);
    });
  });
  auto t1 = std::chrono::steady_clock::now();
  if (grid && (!private_grid_grads_ || n_tail_ > 0)) scatter_grid_gradients(n_static);
  auto t2 = std::chrono::steady_clock::now();
  sum_gradients();
  if (gradient_hook_) gradient_hook_(grads_.data());
  net_.adam_step(adam_, grads_.data());
  auto t3 = std::chrono::steady_clock::now();
  phase_seconds[0] = std::chrono::duration<double>(t1 - t0).count();
  phase_seconds[1] = std::chrono::duration<double>(t2 - t1).count();
  phase_seconds[2] = std::chrono::duration<double>(t3 - t2).count();

  double loss = 0;
  for (double l : chunk_loss_) loss += l;
  loss_history_.push_back(float(loss));
  return float(loss);
}

// The grid backward after the chunks. Levels dealt round-robin: thread t owns levels t, t + nt, ...
// (its writes never overlap another's): every sample into the batch gradient, or a private grid's
// shared chunks into thread t's copy.
void CpuTrainer::scatter_grid_gradients(int64_t n_static) {
  const MlpLayout& m = net_.mlp();
  const int64_t C = kChunk;
  const int64_t s0 = private_grid_grads_ ? n_static * C : 0;
  const int64_t ns = private_grid_grads_ ? n_tail_ * C : opts_.batch;
  const float* dEnc = private_grid_grads_ ? tail_dEnc_.data() : dEnc_.data();
  const uint32_t n_levels = net_.grid().n_levels;
  std::atomic<int64_t> next_level{0};
  parallel_threads([&](int t, int nt) {
    float* ggrid = (private_grid_grads_ ? dW_[t].data() : grads_.data()) + m.n_params;
    auto level = [&](int64_t l) {
      net_.grid_backward_level(uint32_t(l), xs_.data() + s0, ys_.data() + s0, zs_.data() + s0, ns, dEnc, int(C), ggrid);
    };
    // Into the batch gradient each level's writes are its own, whoever makes them: levels go to whichever
    // thread is free. A private copy per thread must get the same levels at every step (the sum of the
    // copies would otherwise round differently): round-robin.
    if (!private_grid_grads_) for_each_claimed(next_level, n_levels, level);
    else for (uint32_t l = uint32_t(t); l < n_levels; l += uint32_t(nt)) level(l);
  });
}

// Sums the per-thread gradients in thread order into grads_, then the shared chunks' MLP gradients
// in chunk order (deterministic for a thread count).
void CpuTrainer::sum_gradients() {
  const MlpLayout& m = net_.mlp();
  float* gm = grads_.data();
  const int64_t n_summed = int64_t(dW_[0].size()), n_mlp = int64_t(m.n_params);
  // Each element's sum is its own: ranges go to whichever thread is free.
  const int64_t grain = std::min<int64_t>(int64_t(1) << 16, (n_summed + n_threads_ - 1) / n_threads_);
  parallel_for_claimed(n_summed, grain, [&](int64_t b, int64_t e) {
    std::memcpy(gm + b, dW_[0].data() + b, sizeof(float) * size_t(e - b));
    for (int t = 1; t < n_threads_; ++t)
      for (int64_t i = b; i < e; ++i) gm[i] += dW_[t][size_t(i)];
    for (int64_t k = 0; k < n_tail_; ++k) {
      const float* tdW = tail_dW_.data() + k * n_mlp;
      for (int64_t i = b; i < std::min(e, n_mlp); ++i) gm[i] += tdW[i];
    }
  });
}

std::array<CpuTrainer::Phase, 3> CpuTrainer::phases() const {
  if (private_grid_grads_)
    return {{{"sample_encode_mlp_grid_backward", "sample+encode+MLP+grid backward (per chunk)"},
             {"grid_backward_shared_chunks", "grid backward (shared chunks)"},
             {"optimizer", "optimizer"}}};
  return {{{"sample_encode_mlp", "sample+encode+MLP"}, {"grid_backward", "grid backward"}, {"optimizer", "optimizer"}}};
}

void CpuTrainer::run(int64_t n_steps) {
  for (int64_t i = 0; i < n_steps; ++i) step();
}

std::vector<Trainer::PhaseTime> CpuTrainer::last_step_phases() const {
  std::vector<PhaseTime> out;
  const std::array<Phase, 3> names = phases();
  for (int p = 0; p < 3; ++p) out.push_back({names[p].key, names[p].name, phase_seconds[p]});
  return out;
}

void CpuTrainer::enable_online_ranges(Int3 dims, int cell_size) {
  thread_ranges_.assign(size_t(n_threads_), ValueRangeGrid(dims, cell_size));
}

ValueRangeGrid CpuTrainer::online_ranges() const {
  if (thread_ranges_.empty()) fail("online macro-cells were not enabled for this training run");
  ValueRangeGrid g = thread_ranges_[0];
  for (size_t t = 1; t < thread_ranges_.size(); ++t) g.merge(thread_ranges_[t]);
  return g;
}

}  // namespace vnr
