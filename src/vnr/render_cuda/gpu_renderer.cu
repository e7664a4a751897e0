// GpuRenderer: the host orchestration of its kernels (see gpu_renderer.h). The per-pixel and per-slot
// work is the shared code of render/: the in-shader loop of inshader_loop.h (inshader_kernels.cuh) and
// the streaming stages of stream_stages.h, launched with core/parallel.h's CUDA parallel_for, in the
// same order as the CPU renderer runs them.
#include <algorithm>
#include <chrono>
#include <cub/cub.cuh>
#include "vnr/core/parallel.h"
#include "vnr/cuda/network.cuh"
#include "vnr/cuda/point_eval.cuh"
#include "vnr/render/stream_driver.h"
#include "vnr/render_cuda/cache_copy.cuh"
#include "vnr/render_cuda/gpu_renderer.h"
#include "vnr/render_cuda/inshader_kernels.cuh"

namespace vnr {

using cuda::DeviceBuffer;
using cuda::blocks_for;
using cuda::cuda_fail_message;
using namespace gpu_render;

namespace {

constexpr int kThreads = 256;
// Streaming: points per batched inference call at most, by default (the rest of an iteration's points go
// in further calls); bounds the network's pass buffers (4M points x 64 encoding columns = 512 MiB of halves).
constexpr int64_t kDefaultInferSlab = int64_t(1) << 22;

__global__ void iota_kernel(int32_t* out, int64_t n) {
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i < n) out[i] = int32_t(i);
}

// The ground-truth grid's batched query.
__global__ void grid_query_kernel(GridView g, const float* __restrict__ xyz, int64_t n, float* __restrict__ out) {
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i < n) out[i] = grid_lookup(g, xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
}

// Per-cell max opacity for a transfer function (MacroCells::update's function).
__global__ void max_opacity_kernel(const Vec4f* __restrict__ table, int n, float tf_lo, float tf_w,
                                   const float* __restrict__ lo, const float* __restrict__ hi, int64_t cells,
                                   float* __restrict__ out) {
  const int64_t c = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (c < cells) out[c] = macrocell_max_opacity(table, n, tf_lo, tf_w, lo[c], hi[c]);
}

// A frame folded into the running mean (frame 0 starts it), and the mean as to_rgba8's bytes: the host's
// running_mean and rgba8_word, uncontracted as there (--fmad=false), so the same bytes.
__global__ void mean_rgba8_kernel(Vec4f* __restrict__ mean, const Vec4f* __restrict__ frame, int64_t n, bool first,
                                  float w, uint32_t* __restrict__ rgba) {
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const Vec4f a = first ? frame[i] : running_mean(mean[i], frame[i], w);
  mean[i] = a;
  rgba[i] = rgba8_word(a);
}

#define VNR_LAUNCH(kernel, n, ...)                                                                   \
  do {                                                                                               \
    if ((n) > 0) {                                                                                   \
      kernel<<<blocks_for((n), kThreads), kThreads, 0, sb.stream>>>(__VA_ARGS__);                    \
      VNR_CUDA_LAUNCHED();                                                                           \
    }                                                                                                \
  } while (0)

}  // namespace

// ---------------------------------------------------------------------------------------------------

struct GpuRenderer::Impl {
  cuda::StreamAndBlas sb;  // first: fails with one line when there is no device
  RenderOptions opt;
  RenderParams p;  // tf.table and mc.max_opacity point into GPU memory
  Vec3f box;
  // the field: a grid, a network (streaming inference + the in-shader warp evaluator), or a brick cache
  std::unique_ptr<DeviceCacheCopy> cache;
  DeviceBuffer<float> volume;
  GridView dvol;
  std::unique_ptr<cuda::DeviceNetwork> dnet;
  cuda::WarpNetwork netf{};
  DeviceBuffer<cuda::WarpNetwork> netf_device;
  // transfer function and macro-cells
  DeviceBuffer<Vec4f> tf_table;  // p.tf views it
  float tf_w = 1;                 // hi - lo of the TF window (macrocell_max_opacity divides by it)
  DeviceBuffer<float> range_lo, range_hi, max_op;
  // frame buffers; the mean of a viewer's frames and its 8-bit image (render_mean_rgba8)
  DeviceBuffer<Vec4f> image, mean;
  DeviceBuffer<uint32_t> mean_rgba8;
  bool mean_started = false;
  DeviceBuffer<MarchState> march;
  DeviceBuffer<ShadowState> shadow;
  DeviceBuffer<PathState> path;
  DeviceBuffer<int32_t> all, live, next;
  DeviceBuffer<uint8_t> keep;
  DeviceBuffer<int64_t> count, offset;
  DeviceBuffer<Vec3f> spos;
  DeviceBuffer<float> sdt, xyz, values;
  DeviceBuffer<int> n_live;
  DeviceBuffer<unsigned long long> samples;
  DeviceBuffer<unsigned char> cub_temp;
  // What the host reads back (pinned): the live-ray count, and a sample total or the in-shader count.
  struct HostCounts {
    int live;
    int64_t total;
    unsigned long long samples;
  };
  HostCounts* host = nullptr;
  int64_t n_pixels = 0;
  int64_t infer_slab = kDefaultInferSlab;

  Impl(const GpuFieldSource& field, Vec3f b, const MacroCells& mc, const TransferFunction& tf, const Camera& cam,
       const RenderOptions& o, cuda::MlpPath mlp)
      : opt(o), box(b) {
    p = make_render_params(field.dims, box, mc, tf, cam, opt);
    if (field.network) {
      dnet = std::make_unique<cuda::DeviceNetwork>(*field.network, mlp);
      // A network the warp MLP's tiles cannot run is drawn by streaming; asked for in-shader,
      // make_warp_network says why.
      if (opt.strategy == RenderStrategy::InShader || mlp_in_16_wide_tiles(field.network->mlp())) bind_warp_network();
    } else if (field.cache) {
      cache = std::make_unique<DeviceCacheCopy>(*field.cache);
    } else if (field.grid.data) {
      const GridView& hv = field.grid;
      const size_t voxels = size_t(hv.nx) * hv.ny * hv.nz;
      volume.resize(voxels);
      volume.upload(hv.data, voxels);
      dvol = GridView{volume.data(), hv.nx, hv.ny, hv.nz};
    } else {
      cuda_fail_message("the GPU renderer needs a grid, a network or a brick cache");
    }
    n_pixels = int64_t(opt.width) * opt.height;
    VNR_CUDA_CHECK(cudaMallocHost(&host, sizeof(HostCounts)));
    samples.resize(1);
    n_live.resize(1);
    image.resize(size_t(n_pixels));
    upload_tf(tf);
    upload_ranges(mc.ranges());
  }
  ~Impl() {
    if (host) cudaFreeHost(host);
  }

  void upload_tf(const TransferFunction& tf) {
    if (tf.table.size() < 2) cuda_fail_message("the transfer function needs at least 2 entries");
    tf_table.resize(tf.table.size());
    tf_table.upload(tf.table.data(), tf.table.size());
    tf_w = tf.hi - tf.lo;
    TfView v = view_of(tf);
    v.table = tf_table.data();
    p.tf = v;
    recompute_opacity();
  }

  void upload_ranges(const ValueRangeGrid& r) {
    MacroCells shape(r, box);  // the cell geometry (world size of a cell)
    const size_t cells = size_t(r.count());
    range_lo.resize(cells);
    range_hi.resize(cells);
    max_op.resize(cells);
    range_lo.upload(r.lo.data(), cells);
    range_hi.upload(r.hi.data(), cells);
    MacroCellView v = shape.view();
    v.max_opacity = max_op.data();
    p.mc = v;
    recompute_opacity();
  }

  void recompute_opacity() {
    if (!max_op.size() || !tf_table.size()) return;
    const int64_t cells = int64_t(max_op.size());
    VNR_LAUNCH(max_opacity_kernel, cells, p.tf.table, p.tf.n, p.tf.lo, tf_w, range_lo.data(), range_hi.data(), cells,
               max_op.data());
  }

  // Field values of n points (interleaved xyz in `xyz`, n a multiple of 16); *stride = floats per value.
  const float* evaluate(int64_t n, int* stride) {
    if (dnet) {
      const int n_out = dnet->dims().n_out;
      *stride = n_out;
      if (n <= infer_slab) return dnet->infer(xyz.data(), n, sb);
      // in slabs: the pass buffers (n x encoding width halves, ...) stay bounded whatever the image size
      if (values.size() < size_t(n) * n_out) values.resize(size_t(n) * n_out);
      for (int64_t b = 0; b < n; b += infer_slab) {
        const int64_t m = std::min(infer_slab, n - b);  // multiples of 16: n and the slab are
        const float* out = dnet->infer(xyz.data() + 3 * b, m, sb);
        VNR_CUDA_CHECK(cudaMemcpyAsync(values.data() + b * n_out, out, size_t(m) * n_out * sizeof(float),
                                       cudaMemcpyDeviceToDevice, sb.stream));
      }
      return values.data();
    }
    if (values.size() < size_t(n)) values.resize(size_t(n));
    VNR_LAUNCH(grid_query_kernel, n, dvol, xyz.data(), n, values.data());
    *stride = 1;
    return values.data();
  }

  // A per-slot stage (stream_stages.h) over [0, n) on the renderer's stream.
  template <class Stage>
  void run(int64_t n, const Stage& stage) {
    parallel_for(sb.stream, n, stage, kThreads);
    VNR_CUDA_LAUNCHED();
  }
  static PointSink interleaved(float* xyz) { return PointSink{xyz, xyz + 1, xyz + 2, 3}; }

  void ensure_points(int64_t n) {
    if (xyz.size() < size_t(3 * n)) xyz.resize(size_t(3 * std::max<int64_t>(n, 1 << 16)));
  }

  void ensure_queues() {
    if (all.size()) return;
    all.resize(size_t(n_pixels));
    live.resize(size_t(n_pixels));
    next.resize(size_t(n_pixels));
    keep.resize(size_t(n_pixels));
    count.resize(size_t(n_pixels) + 1);
    offset.resize(size_t(n_pixels) + 1);
    VNR_LAUNCH(iota_kernel, n_pixels, all.data(), n_pixels);
    // CUB's scratch for the largest select and scan of a frame
    size_t a = 0, b = 0;
    VNR_CUDA_CHECK(cub::DeviceSelect::Flagged(nullptr, a, all.data(), keep.data(), live.data(), n_live.data(),
                                              int(n_pixels), sb.stream));
    VNR_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(nullptr, b, count.data(), offset.data(), int(n_pixels) + 1,
                                                 sb.stream));
    cub_temp.resize(std::max(a, b));
  }

  // live[0, *n_live) = the entries of `in` [0, n) whose keep flag is set (order kept).
  void compact(const int32_t* in, int64_t n, int32_t* out) {
    size_t bytes = cub_temp.size();
    VNR_CUDA_CHECK(cub::DeviceSelect::Flagged(cub_temp.data(), bytes, in, keep.data(), out, n_live.data(), int(n),
                                              sb.stream));
  }

  // Waits for the device and returns the live-ray count (and a sample total, when given).
  int64_t read_counts(const int64_t* total_on_device, int64_t* total, RenderStats& st) {
    VNR_CUDA_CHECK(cudaMemcpyAsync(&host->live, n_live.data(), sizeof(int), cudaMemcpyDeviceToHost, sb.stream));
    if (total_on_device)
      VNR_CUDA_CHECK(
          cudaMemcpyAsync(&host->total, total_on_device, sizeof(int64_t), cudaMemcpyDeviceToHost, sb.stream));
    VNR_CUDA_CHECK(cudaStreamSynchronize(sb.stream));
    st.host_syncs += 1;
    if (total) *total = host->total;
    return host->live;
  }

  // The GPU backend of the streaming driver (render/stream_driver.h): the queues in GPU memory, CUB
  // scan and selection, one host synchronisation per iteration (the coordinate stage of the next
  // iteration runs over the previous live count, an upper bound, and reads the exact one on the GPU).
  struct StreamBackend {
    Impl& I;
    template <class Stage>
    void run(int64_t n, const Stage& stage) { I.run(n, stage); }
    MarchState* march_states(int64_t n) { return resized(I.march, n); }
    ShadowState* shadow_states(int64_t n) { return resized(I.shadow, n); }
    PathState* path_states(int64_t n) { return resized(I.path, n); }
    uint8_t* pixel_keep(int64_t) { return I.keep.data(); }  // n_pixels (ensure_queues)
    int64_t start_queue() {
      I.compact(I.all.data(), I.n_pixels, I.live.data());
      return I.n_pixels;
    }
    int64_t live_count(RenderStats& st) { return I.read_counts(nullptr, nullptr, st); }
    int32_t* live() { return I.live.data(); }
    const int* n_live() { return I.n_live.data(); }
    uint8_t* keep() { return I.keep.data(); }
    void slots(int64_t, int K) {  // count and offset hold n_pixels + 1 (ensure_queues)
      if (I.spos.size() < size_t(I.n_pixels) * K) {
        I.spos.resize(size_t(I.n_pixels) * K);
        I.sdt.resize(size_t(I.n_pixels) * K);
      }
    }
    Vec3f* spos() { return I.spos.data(); }
    float* sdt() { return I.sdt.data(); }
    int64_t* count() { return I.count.data(); }
    int64_t* offset() { return I.offset.data(); }
    int64_t scan(int64_t cap, int64_t* total, RenderStats& st) {
      size_t bytes = I.cub_temp.size();
      VNR_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(I.cub_temp.data(), bytes, I.count.data(), I.offset.data(),
                                                   int(cap) + 1, I.sb.stream));
      return I.read_counts(I.offset.data() + cap, total, st);
    }
    PointSink points(int64_t n) {
      I.ensure_points(cuda::round_up(n, 16));
      return interleaved(I.xyz.data());
    }
    // The batched networks take multiples of 16 points: the rest is padded with zeros.
    const float* query(int64_t n, int* stride, RenderStats&) {
      if (n == 0) return nullptr;  // every live ray ended in its coordinate stage: the shading drops them
      const int64_t n_padded = cuda::round_up(n, 16);
      if (n_padded > n)
        VNR_CUDA_CHECK(cudaMemsetAsync(I.xyz.data() + 3 * n, 0, size_t(3 * (n_padded - n)) * 4, I.sb.stream));
      return I.evaluate(n_padded, stride);
    }
    int64_t compact(int64_t n) {  // the exact count stays on the GPU until the next scan
      I.compact(I.live.data(), n, I.next.data());
      std::swap(I.live, I.next);
      return n;
    }
    template <class T>
    static T* resized(DeviceBuffer<T>& b, int64_t n) {
      b.resize(size_t(n));
      return b.data();
    }
  };

  void stream(RenderStats& st) {
    ensure_queues();
    StreamBackend b{*this};
    if (opt.mode == RenderMode::PathTrace)
      stream_path_frame(b, p, image.data(), st);
    else
      stream_march_frame(b, p, opt.mode == RenderMode::Shadow, opt.samples_per_iteration, image.data(), st);
  }

  template <class Field>
  void inshader(const Field& f, size_t smem, RenderStats& st) {
    VNR_CUDA_CHECK(cudaMemsetAsync(samples.data(), 0, sizeof(unsigned long long), sb.stream));
    const int mode = opt.mode == RenderMode::PathTrace ? 2 : (opt.mode == RenderMode::Shadow ? 1 : 0);
    launch_inshader(p, f, smem, mode, image.data(), samples.data(), sb.stream);
    VNR_CUDA_CHECK(cudaMemcpyAsync(&host->samples, samples.data(), sizeof(unsigned long long), cudaMemcpyDeviceToHost,
                                   sb.stream));
    VNR_CUDA_CHECK(cudaStreamSynchronize(sb.stream));
    st.host_syncs += 1;
    st.field_samples += int64_t(host->samples);
  }

  void bind_warp_network() {
    netf = cuda::make_warp_network(*dnet, kWarpsPerBlock);
    netf_device.resize(1);
    netf_device.upload(&netf, 1);
    const bool supported = with_feature_count(netf.grid.n_features, [&](auto F) {  // once: the grid's F
      allow_inshader_smem<F()>(int(netf.smem_bytes()));
      inshader_network = &Impl::inshader_network_of<F()>;
    });
    if (!supported)
      cuda::cuda_fail_message("no in-shader kernels for " + std::to_string(netf.grid.n_features) + " features per level");
  }

  template <int NF>
  void inshader_network_of(RenderStats& st) {
    inshader(cuda::WarpNetworkRef<NF>{netf_device.data()}, netf.smem_bytes(), st);
  }
  void (Impl::*inshader_network)(RenderStats&) = nullptr;  // inshader_network_of the grid's F

  void render(uint32_t frame, RenderStats& st) {
    const auto t0 = std::chrono::steady_clock::now();
    p.frame = frame;
    if (cache) {  // one lookup a sample: in-shader whatever the strategy (as for a grid, nothing to batch)
      cache->begin_frame(p);
      inshader(cache->field(), 0, st);
      cache->end_frame(sb.stream);
    } else if (opt.strategy == RenderStrategy::Streaming) {
      stream(st);
      VNR_CUDA_CHECK(cudaStreamSynchronize(sb.stream));
      st.host_syncs += 1;
    } else if (dnet) {
      (this->*inshader_network)(st);
    } else {
      inshader(GridWarpField{dvol}, 0, st);
    }
    st.frames += 1;
    st.rays += n_pixels;
    st.seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
};

GpuRenderer::GpuRenderer(const GpuFieldSource& field, Vec3f box, const MacroCells& mc, const TransferFunction& tf,
                         const Camera& cam, const RenderOptions& opt, cuda::MlpPath mlp)
    : impl_(std::make_unique<Impl>(field, box, mc, tf, cam, opt, mlp)) {}
GpuRenderer::~GpuRenderer() = default;

void GpuRenderer::render_frame_resident(uint32_t frame, RenderStats* stats) {
  RenderStats local;
  impl_->render(frame, stats ? *stats : local);
}

void GpuRenderer::render_frame(uint32_t frame, Image& img, RenderStats* stats) {
  render_frame_resident(frame, stats);
  Impl& I = *impl_;
  if (img.width != I.opt.width || img.height != I.opt.height) img = Image(I.opt.width, I.opt.height);
  I.image.download(img.pixels.data(), img.pixels.size());
}

void GpuRenderer::render_mean_rgba8(uint32_t frame, std::vector<uint8_t>& rgba) {
  render_frame_resident(frame);
  Impl& I = *impl_;
  const int64_t n = I.n_pixels;
  I.mean.resize(size_t(n));
  I.mean_rgba8.resize(size_t(n));
  auto& sb = I.sb;
  VNR_LAUNCH(mean_rgba8_kernel, n, I.mean.data(), I.image.data(), n, frame == 0 || !I.mean_started,
             1.0f / float(frame + 1), I.mean_rgba8.data());
  I.mean_started = true;
  rgba.resize(size_t(n) * 4);
  VNR_CUDA_CHECK(cudaMemcpyAsync(rgba.data(), I.mean_rgba8.data(), size_t(n) * 4, cudaMemcpyDeviceToHost, sb.stream));
  VNR_CUDA_CHECK(cudaStreamSynchronize(sb.stream));
}

void GpuRenderer::set_camera(const Camera& cam) { set_render_camera(impl_->p, cam, impl_->opt); }

bool GpuRenderer::refresh_network(const MacroCells& mc, const void* device_half) {
  Impl& I = *impl_;
  if (I.cache) {  // the host cache refreshes its bricks itself (CachedField::replace_source)
    I.upload_ranges(mc.ranges());
    return true;
  }
  if (!I.dnet || !device_half) return false;
  VNR_CUDA_CHECK(cudaStreamSynchronize(I.sb.stream));  // no frame reads the parameters while they change
  I.dnet->reload_params(device_half);
  I.upload_ranges(mc.ranges());
  return true;
}

void GpuRenderer::set_transfer_function(const TransferFunction& tf) { impl_->upload_tf(tf); }
void GpuRenderer::set_ranges(const ValueRangeGrid& ranges) { impl_->upload_ranges(ranges); }

std::vector<float> GpuRenderer::max_opacity() {
  VNR_CUDA_CHECK(cudaStreamSynchronize(impl_->sb.stream));
  std::vector<float> out(impl_->max_op.size());
  impl_->max_op.download(out.data(), out.size());
  return out;
}

cuda::MlpPath GpuRenderer::mlp_path() const {
  return impl_->dnet ? impl_->dnet->path() : cuda::MlpPath::Auto;
}
void GpuRenderer::set_inference_slab(int64_t points) {
  impl_->infer_slab = std::max<int64_t>(16, cuda::round_up(points, 16));
}
bool GpuRenderer::inshader_weights_shared() const { return impl_->dnet && impl_->netf.stage; }

ValueRangeGrid gpu_value_ranges_from_grid(const GridView& g, int cell_size) {
  cuda::require_device();
  ValueRangeGrid out(Int3{g.nx, g.ny, g.nz}, cell_size);
  const size_t voxels = size_t(g.nx) * g.ny * g.nz, cells = size_t(out.count());
  DeviceBuffer<float> vol(voxels), lo(cells), hi(cells);
  vol.upload(g.data, voxels);
  // the legacy default stream: ordered with the synchronous copies around it
  cuda::ranges_from_grid(GridView{vol.data(), g.nx, g.ny, g.nz}, cuda::range_grid_dims(out), lo.data(), hi.data(),
                         nullptr);
  lo.download(out.lo.data(), cells);
  hi.download(out.hi.data(), cells);
  return out;
}

}  // namespace vnr
