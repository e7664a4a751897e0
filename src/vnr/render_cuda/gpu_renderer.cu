// GpuRenderer: the kernels and their host orchestration (see gpu_renderer.h). Every per-ray step is a
// VNR_HD function of render/integrators.h, called in the same order as the CPU renderer calls it.
#include <mma.h>
#include <algorithm>
#include <chrono>
#include <cub/cub.cuh>
#include "vnr/cuda/grid_device.cuh"
#include "vnr/cuda/network.cuh"
#include "vnr/nn/loss.h"
#include "vnr/render/integrators.h"
#include "vnr/render_cuda/gpu_renderer.h"

namespace vnr {

using cuda::DeviceBuffer;
using cuda::MlpDims;
using cuda::blocks_for;
using cuda::cuda_fail_message;
namespace wmma = nvcuda::wmma;

namespace {

constexpr unsigned kFull = 0xffffffffu;
constexpr int kThreads = 256;
// In-shader: a block of 4 warps covers 16 x 8 pixels, each warp 8 x 4 (neighbouring rays, neighbouring
// samples: coherent hash-grid reads and few idle lanes).
constexpr int kWarpsPerBlock = 4;
constexpr int kBlockW = 16, kBlockH = 8;
// Streaming: points per batched inference call at most, by default (the rest of an iteration's points go
// in further calls); bounds the network's pass buffers (4M points x 64 encoding columns = 512 MiB of halves).
constexpr int64_t kDefaultInferSlab = int64_t(1) << 22;

// ---------------------------------------------------------------------------------------------------
// Fields as seen by one warp of an in-shader kernel. bind() runs once per thread at the start of the
// kernel (all threads of the block: it may stage data in shared memory); the bound evaluator's
// operator() is then called by all 32 lanes of a warp together, `active` saying whose sample counts.

struct GridWarpField {
  GridView g;
  struct Eval {
    GridView g;
    __device__ float operator()(bool active, float x, float y, float z) const {
      return active ? grid_lookup(g, x, y, z) : 0.0f;
    }
  };
  __device__ Eval bind(unsigned char*) const { return Eval{g}; }
};

// The grid encoding of one point into one row of halves (the encode kernel's values, one thread doing
// every level), pad columns zeroed.
__device__ inline void encode_row(const GridLayout& g, const __half* table, float x, float y, float z, __half* row,
                                  int in_pad) {
  const int F = int(g.n_features), L = int(g.n_levels);
  for (int l = 0; l < L; ++l) {
    float out[8];
    switch (F) {
      case 1: cuda::grid_level_forward_half<1>(g.levels[l], g.interpolation, table, x, y, z, out); break;
      case 2: cuda::grid_level_forward_half<2>(g.levels[l], g.interpolation, table, x, y, z, out); break;
      case 4: cuda::grid_level_forward_half<4>(g.levels[l], g.interpolation, table, x, y, z, out); break;
      default: cuda::grid_level_forward_half<8>(g.levels[l], g.interpolation, table, x, y, z, out); break;
    }
    for (int f = 0; f < F; ++f) row[l * F + f] = __float2half_rn(out[f]);
  }
  for (int k = L * F; k < in_pad; ++k) row[k] = __float2half_rn(0.0f);
}

// A network evaluated warp-cooperatively (the paper's appendix "In-Shader Inference Details"): each lane
// encodes its point into its row of the warp's 32-row activation tile; the warp multiplies the two 16-row
// halves by each weight matrix with WMMA 16x16x16 (half in, binary32 accumulate, ReLU, rounded to half:
// the fused kernels' arithmetic), skipping a half whose lanes are all idle.
struct NetWarpField {
  GridLayout grid;
  const __half* table;     // half grid parameters
  const __half* weights;   // half MLP weights in GPU memory (tcnn order)
  MlpDims d;
  int out_act;
  int ld;                  // row stride of the activation tiles, halves
  uint32_t n_weights;      // halves
  int stage;               // 1: the weights are copied to shared memory

  // Shared memory per block: the staged weights, then per warp two 32-row tiles and a 16x16 binary32 tile.
  __host__ __device__ size_t weight_bytes() const { return stage ? (size_t(n_weights) * 2 + 127) / 128 * 128 : 0; }
  __host__ __device__ size_t warp_bytes() const { return size_t(2) * 32 * ld * 2 + 256 * 4; }
  __host__ __device__ size_t smem_bytes() const { return weight_bytes() + kWarpsPerBlock * warp_bytes(); }

  struct Eval {
    const NetWarpField* F;
    const __half* w;
    __half *a0, *a1;
    float* f;
    int lane;

    __device__ float operator()(bool active, float x, float y, float z) const {
      const unsigned act = __ballot_sync(kFull, active);
      if (act == 0) return 0.0f;
      const MlpDims& d = F->d;
      const int ld = F->ld;
      if (active) encode_row(F->grid, F->table, x, y, z, a0 + lane * ld, d.in_pad);
      __syncwarp();
      float result = 0.0f;
      for (int t = 0; t < 2; ++t) {
        if (((act >> (16 * t)) & 0xffffu) == 0) continue;  // warp-uniform
        __half* in = a0 + t * 16 * ld;
        __half* out = a1 + t * 16 * ld;
        for (int m = 0; m < d.n_matrices; ++m) {
          const int rows = d.rows[m], cols = d.cols[m];
          const bool last = m == d.n_matrices - 1;
          const __half* wm = w + d.offset[m];
          const int nbs = last ? 1 : rows / 16;  // the output layer: the first 16 outputs hold the one we need
          for (int nb = 0; nb < nbs; ++nb) {
            wmma::fragment<wmma::accumulator, 16, 16, 16, float> acc;
            wmma::fill_fragment(acc, 0.0f);
            for (int kb = 0; kb < cols / 16; ++kb) {
              wmma::fragment<wmma::matrix_a, 16, 16, 16, __half, wmma::row_major> a;
              wmma::fragment<wmma::matrix_b, 16, 16, 16, __half, wmma::col_major> b;  // (k, j) = W[j][k]
              wmma::load_matrix_sync(a, in + kb * 16, ld);
              wmma::load_matrix_sync(b, wm + nb * 16 * cols + kb * 16, cols);
              wmma::mma_sync(acc, a, b, acc);
            }
            if (!last)
              for (int i = 0; i < acc.num_elements; ++i) acc.x[i] = acc.x[i] > 0.0f ? acc.x[i] : 0.0f;
            wmma::store_matrix_sync(f, acc, 16, wmma::mem_row_major);
            __syncwarp();
            if (last) {
              if ((lane >> 4) == t) result = f[(lane & 15) * 16];
            } else {
              for (int i = lane; i < 256; i += 32) out[(i >> 4) * ld + nb * 16 + (i & 15)] = __float2half_rn(f[i]);
            }
            __syncwarp();
          }
          __half* tmp = in;
          in = out;
          out = tmp;
        }
      }
      return activate(Activation(F->out_act), result);
    }
  };

};

// What the in-shader kernels take for a network: the NetWarpField in GPU memory (read through the
// cache, warp-uniform), not a kernel-parameter copy that dynamic indexing would move to local memory.
struct NetWarpRef {
  const NetWarpField* F;
  using Eval = NetWarpField::Eval;
  __device__ Eval bind(unsigned char* smem) const {
    const NetWarpField& f = *F;
    const int ld = f.ld;
    Eval e;
    e.F = F;
    e.lane = int(threadIdx.x % 32);
    const int warp = int(threadIdx.x / 32);
    unsigned char* base = smem + f.weight_bytes() + size_t(warp) * f.warp_bytes();
    e.a0 = reinterpret_cast<__half*>(base);
    e.a1 = e.a0 + 32 * ld;
    e.f = reinterpret_cast<float*>(e.a1 + 32 * ld);
    // zero the tiles: idle lanes' rows then hold finite values
    for (int i = e.lane; i < 2 * 32 * ld; i += 32) e.a0[i] = __float2half_rn(0.0f);
    if (f.stage) {
      __half* ws = reinterpret_cast<__half*>(smem);
      const uint4* src = reinterpret_cast<const uint4*>(f.weights);
      uint4* dst = reinterpret_cast<uint4*>(ws);
      for (uint32_t i = threadIdx.x; i < f.n_weights / 8; i += blockDim.x) dst[i] = src[i];
      e.w = ws;
    } else {
      e.w = f.weights;
    }
    __syncthreads();
    return e;
  }
};

// The pixel of a thread in the in-shader kernels.
__device__ inline bool inshader_pixel(const RenderParams& p, int* ix, int* iy) {
  const int warp = int(threadIdx.x / 32), lane = int(threadIdx.x % 32);
  *ix = int(blockIdx.x) * kBlockW + (warp % 2) * 8 + lane % 8;
  *iy = int(blockIdx.y) * kBlockH + (warp / 2) * 4 + lane / 8;
  return *ix < p.cam.width && *iy < p.cam.height;
}

// The start of every in-shader kernel: the field bound to the block's shared memory and the thread's
// pixel (out-of-image threads stay, inactive: the field evaluation is warp-cooperative).
template <class Field>
struct InshaderThread {
  typename Field::Eval eval;
  int ix, iy;
  bool in_image;
  __device__ InshaderThread(const RenderParams& p, const Field& field, unsigned char* smem)
      : eval(field.bind(smem)) {
    in_image = inshader_pixel(p, &ix, &iy);
  }
  __device__ int64_t pixel(const RenderParams& p) const { return int64_t(iy) * p.cam.width + ix; }
};

__device__ inline void count_samples(unsigned long long my, unsigned long long* total) {
  for (int off = 16; off > 0; off /= 2) my += __shfl_down_sync(kFull, my, off);
  if (threadIdx.x % 32 == 0 && my) atomicAdd(total, my);
}

// In-shader ray marching (shadow = 1: and the single-shot shadow ray), M field points per sample.
// Every lane stays in the loops until its whole warp is done (the field evaluation is cooperative).
template <class Field, int M>
__global__ void __launch_bounds__(kWarpsPerBlock * 32)
    inshader_march(RenderParams p, Field field, int shadow, Vec4f* __restrict__ img, unsigned long long* samples) {
  extern __shared__ __align__(128) unsigned char smem[];
  const InshaderThread<Field> t(p, field, smem);
  const auto& eval = t.eval;
  unsigned long long my = 0;
  MarchState s;
  bool active = t.in_image && march_begin(p, t.ix, t.iy, s);
  Vec3f pos{0, 0, 0};
  float dt = 0;
  for (;;) {
    if (active) active = march_next(p, s, &pos, &dt);
    if (!__any_sync(kFull, active)) break;
    float x[M], y[M], z[M], v[M];
    march_sample_points(p, pos, M, x, y, z);
    for (int k = 0; k < M; ++k) v[k] = eval(active, x[k], y[k], z[k]);
    if (active) {
      my += M;
      active = march_shade(p, s, pos, dt, v, M);
    }
  }
  if (shadow) {
    ShadowState sh;
    sh.T = 1;
    active = t.in_image && shadow_begin(p, s, sh);
    for (;;) {
      if (active) active = shadow_next(p, sh, &pos, &dt);
      if (!__any_sync(kFull, active)) break;
      const Vec3f u = pos * p.inv_box;
      const float v = eval(active, u.x, u.y, u.z);
      if (active) {
        my += 1;
        active = shadow_shade(p, sh, v, dt);
      }
    }
    if (t.in_image) img[t.pixel(p)] = shadow_pixel(p, s, sh.T);
  } else if (t.in_image) {
    img[t.pixel(p)] = march_pixel(p, s);
  }
  count_samples(my, samples);
}

// In-shader path tracing: the sample()/shade() state machine of one path per thread.
template <class Field>
__global__ void __launch_bounds__(kWarpsPerBlock * 32)
    inshader_path(RenderParams p, Field field, Vec4f* __restrict__ img, unsigned long long* samples) {
  extern __shared__ __align__(128) unsigned char smem[];
  const InshaderThread<Field> t(p, field, smem);
  const auto& eval = t.eval;
  unsigned long long my = 0;
  PathState s;
  bool active = t.in_image && pt_begin(p, t.ix, t.iy, s) && pt_sample(p, s);
  for (;;) {
    if (!__any_sync(kFull, active)) break;
    const Vec3f u = active ? s.pos * p.inv_box : Vec3f{0, 0, 0};
    const float v = eval(active, u.x, u.y, u.z);
    if (active) {
      my += 1;
      active = pt_shade(p, s, v) && pt_sample(p, s);
    }
  }
  if (t.in_image) img[t.pixel(p)] = pt_pixel(s);
  count_samples(my, samples);
}

// ---------------------------------------------------------------------------------------------------
// Sample streaming. The per-ray work of a pass (primary rays, shadow rays) as a small POD of device
// pointers; the stages are generic over it.

struct MarchOps {
  MarchState* s;
  int m;  // points per sample (1, or 7 with shading)
  __device__ bool next(const RenderParams& p, int32_t i, Vec3f* pos, float* dt) const {
    return march_next(p, s[i], pos, dt);
  }
  __device__ void points(const RenderParams& p, Vec3f pos, float* x, float* y, float* z) const {
    march_sample_points(p, pos, m, x, y, z);
  }
  __device__ bool shade(const RenderParams& p, int32_t i, Vec3f pos, float dt, const float* v) const {
    return march_shade(p, s[i], pos, dt, v, m);
  }
};

struct ShadowOps {
  ShadowState* s;
  static constexpr int m = 1;
  __device__ bool next(const RenderParams& p, int32_t i, Vec3f* pos, float* dt) const {
    return shadow_next(p, s[i], pos, dt);
  }
  __device__ void points(const RenderParams& p, Vec3f pos, float* x, float* y, float* z) const {
    const Vec3f u = pos * p.inv_box;
    *x = u.x, *y = u.y, *z = u.z;
  }
  __device__ bool shade(const RenderParams& p, int32_t i, Vec3f, float dt, const float* v) const {
    return shadow_shade(p, s[i], v[0], dt);
  }
};

__global__ void iota_kernel(int32_t* out, int64_t n) {
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i < n) out[i] = int32_t(i);
}

__global__ void march_begin_kernel(RenderParams p, MarchState* __restrict__ s, uint8_t* __restrict__ keep) {
  const int64_t n = int64_t(p.cam.width) * p.cam.height;
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i < n) keep[i] = march_begin(p, int(i % p.cam.width), int(i / p.cam.width), s[i]);
}

__global__ void shadow_begin_kernel(RenderParams p, const MarchState* __restrict__ m, ShadowState* __restrict__ s,
                                    uint8_t* __restrict__ keep) {
  const int64_t n = int64_t(p.cam.width) * p.cam.height;
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i < n) keep[i] = shadow_begin(p, m[i], s[i]);
}

__global__ void march_pixel_kernel(RenderParams p, const MarchState* __restrict__ m,
                                   const ShadowState* __restrict__ sh, Vec4f* __restrict__ img) {
  const int64_t n = int64_t(p.cam.width) * p.cam.height;
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i < n) img[i] = sh ? shadow_pixel(p, m[i], sh[i].T) : march_pixel(p, m[i]);
}

// Coordinate stage: up to K samples of each live ray r < *n_live (its positions and steps in slots
// r*K ...), count[r] of them; count[r] = 0 for the rest of [0, cap], so a scan over cap + 1 counts
// gives the packed offsets and, at [cap], the total.
template <class Ops>
__global__ void stream_next_kernel(RenderParams p, Ops ops, const int32_t* __restrict__ live,
                                   const int* __restrict__ n_live, int64_t cap, int K, Vec3f* __restrict__ spos,
                                   float* __restrict__ sdt, int64_t* __restrict__ count) {
  const int64_t r = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (r > cap) return;
  int c = 0;
  if (r < *n_live) {
    const int32_t i = live[r];
    while (c < K && ops.next(p, i, &spos[r * K + c], &sdt[r * K + c])) ++c;
  }
  count[r] = c;
}

// Packs the samples' field points (interleaved xyz) at their scanned offsets.
template <class Ops>
__global__ void stream_emit_kernel(RenderParams p, Ops ops, int64_t n_live, int K, const Vec3f* __restrict__ spos,
                                   const int64_t* __restrict__ count, const int64_t* __restrict__ offset,
                                   float* __restrict__ xyz) {
  const int64_t r = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (r >= n_live) return;
  for (int k = 0; k < int(count[r]); ++k) {
    float x[7], y[7], z[7];
    ops.points(p, spos[r * K + k], x, y, z);
    float* q = xyz + (offset[r] + k) * ops.m * 3;
    for (int j = 0; j < ops.m; ++j) {
      q[3 * j] = x[j];
      q[3 * j + 1] = y[j];
      q[3 * j + 2] = z[j];
    }
  }
}

// Shading stage: consumes each live ray's values; keep[r] = the ray goes on (it used all K slots and
// did not terminate).
template <class Ops>
__global__ void stream_shade_kernel(RenderParams p, Ops ops, const int32_t* __restrict__ live, int64_t n_live, int K,
                                    const Vec3f* __restrict__ spos, const float* __restrict__ sdt,
                                    const int64_t* __restrict__ count, const int64_t* __restrict__ offset,
                                    const float* __restrict__ values, int stride, uint8_t* __restrict__ keep) {
  const int64_t r = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (r >= n_live) return;
  const int32_t i = live[r];
  const int c = int(count[r]);
  bool alive = c == K;
  for (int k = 0; k < c; ++k) {
    float v[7];
    const int64_t q = (offset[r] + k) * ops.m;
    for (int j = 0; j < ops.m; ++j) v[j] = values[(q + j) * stride];
    if (!ops.shade(p, i, spos[r * K + k], sdt[r * K + k], v)) {
      alive = false;
      break;
    }
  }
  keep[r] = alive;
}

// Path tracing: ray generation absorbs the first sample() (paper: raygen_kernel<PT_RAY>).
__global__ void path_begin_kernel(RenderParams p, PathState* __restrict__ s, uint8_t* __restrict__ keep,
                                  Vec4f* __restrict__ img) {
  const int64_t n = int64_t(p.cam.width) * p.cam.height;
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const bool k = pt_begin(p, int(i % p.cam.width), int(i / p.cam.width), s[i]) && pt_sample(p, s[i]);
  keep[i] = k;
  if (!k) img[i] = pt_pixel(s[i]);
}

__global__ void path_coords_kernel(RenderParams p, const PathState* __restrict__ s, const int32_t* __restrict__ live,
                                   int64_t n_live, int64_t n_padded, float* __restrict__ xyz) {
  const int64_t r = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (r >= n_padded) return;
  const Vec3f u = r < n_live ? s[live[r]].pos * p.inv_box : Vec3f{0, 0, 0};
  xyz[3 * r] = u.x;
  xyz[3 * r + 1] = u.y;
  xyz[3 * r + 2] = u.z;
}

__global__ void path_shade_kernel(RenderParams p, PathState* __restrict__ s, const int32_t* __restrict__ live,
                                  int64_t n_live, const float* __restrict__ values, int stride,
                                  uint8_t* __restrict__ keep, Vec4f* __restrict__ img) {
  const int64_t r = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (r >= n_live) return;
  const int32_t i = live[r];
  const bool k = pt_shade(p, s[i], values[r * stride]) && pt_sample(p, s[i]);
  keep[r] = k;
  if (!k) img[i] = pt_pixel(s[i]);
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
  // the field: a grid, or a network (streaming inference + the in-shader warp evaluator)
  DeviceBuffer<float> volume;
  GridView dvol;
  std::unique_ptr<cuda::DeviceNetwork> dnet;
  NetWarpField netf{};
  DeviceBuffer<NetWarpField> netf_device;
  // transfer function and macro-cells
  DeviceBuffer<Vec4f> tf_table;  // p.tf views it
  float tf_w = 1;                 // hi - lo of the TF window (macrocell_max_opacity divides by it)
  DeviceBuffer<float> range_lo, range_hi, max_op;
  // frame buffers
  DeviceBuffer<Vec4f> image;
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

  Impl(const Field& field, Vec3f b, const MacroCells& mc, const TransferFunction& tf, const Camera& cam,
       const RenderOptions& o, cuda::MlpPath mlp)
      : opt(o), box(b) {
    p = make_render_params(field.dims(), box, mc, tf, cam, opt);
    if (auto* g = dynamic_cast<const GridField*>(&field)) {
      const GridView& hv = g->view();
      const size_t voxels = size_t(hv.nx) * hv.ny * hv.nz;
      volume.resize(voxels);
      volume.upload(hv.data, voxels);
      dvol = GridView{volume.data(), hv.nx, hv.ny, hv.nz};
    } else if (auto* nf = dynamic_cast<const NetworkField*>(&field)) {
      dnet = std::make_unique<cuda::DeviceNetwork>(nf->network(), mlp);
      setup_warp_network();
    } else {
      cuda_fail_message("the GPU renderer needs a grid or network field");
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

  void setup_warp_network() {
    const Network& net = dnet->network();
    const MlpDims& d = dnet->dims();
    NetWarpField& f = netf;
    f.grid = net.grid();
    f.weights = dnet->half_params();
    f.table = dnet->half_params() + net.mlp().n_params;
    f.d = d;
    f.out_act = int(net.config().network.output_activation);
    f.ld = std::max(d.in_pad, d.width) + 8;  // +8 halves: fewer shared-memory bank conflicts
    f.n_weights = uint32_t(net.mlp().n_params);
    int dev = 0, optin = 0;
    VNR_CUDA_CHECK(cudaGetDevice(&dev));
    VNR_CUDA_CHECK(cudaDeviceGetAttribute(&optin, cudaDevAttrMaxSharedMemoryPerBlockOptin, dev));
    f.stage = 1;
    if (f.smem_bytes() > size_t(optin)) f.stage = 0;  // weights through L1 instead
    if (f.smem_bytes() > size_t(optin))
      cuda_fail_message("in-shader inference: the MLP's activation tiles need " + std::to_string(f.smem_bytes()) +
                        " bytes of shared memory per block, the device has " + std::to_string(optin));
    netf_device.resize(1);
    netf_device.upload(&f, 1);
    const int bytes = int(f.smem_bytes());
    VNR_CUDA_CHECK(cudaFuncSetAttribute(inshader_march<NetWarpRef, 1>,
                                        cudaFuncAttributeMaxDynamicSharedMemorySize, bytes));
    VNR_CUDA_CHECK(cudaFuncSetAttribute(inshader_march<NetWarpRef, 7>,
                                        cudaFuncAttributeMaxDynamicSharedMemorySize, bytes));
    VNR_CUDA_CHECK(cudaFuncSetAttribute(inshader_path<NetWarpRef>, cudaFuncAttributeMaxDynamicSharedMemorySize,
                                        bytes));
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

  // One streaming pass (primary or shadow rays) over the rays whose keep flag is set.
  template <class Ops>
  void stream_pass(const Ops& ops, RenderStats& st) {
    const int K = opt.samples_per_iteration;
    compact(all.data(), n_pixels, live.data());
    if (spos.size() < size_t(n_pixels) * K) {
      spos.resize(size_t(n_pixels) * K);
      sdt.resize(size_t(n_pixels) * K);
    }
    int64_t cap = n_pixels;  // an upper bound of the live rays
    for (;;) {
      VNR_LAUNCH(stream_next_kernel<Ops>, cap + 1, p, ops, live.data(), n_live.data(), cap, K, spos.data(), sdt.data(),
                 count.data());
      size_t bytes = cub_temp.size();
      VNR_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(cub_temp.data(), bytes, count.data(), offset.data(), int(cap) + 1,
                                                   sb.stream));
      int64_t n_samples = 0;
      const int64_t nl = read_counts(offset.data() + cap, &n_samples, st);
      if (nl == 0) break;
      const int64_t n_points = n_samples * ops.m, n_padded = cuda::round_up(n_points, 16);
      ensure_points(n_padded);
      VNR_LAUNCH(stream_emit_kernel<Ops>, nl, p, ops, nl, K, spos.data(), count.data(), offset.data(), xyz.data());
      if (n_padded > n_points)
        VNR_CUDA_CHECK(cudaMemsetAsync(xyz.data() + 3 * n_points, 0, size_t(3 * (n_padded - n_points)) * 4, sb.stream));
      int stride = 1;
      // every live ray may have ended in its coordinate stage: nothing to evaluate, the shading stage drops them
      const float* v = n_padded > 0 ? evaluate(n_padded, &stride) : nullptr;
      VNR_LAUNCH(stream_shade_kernel<Ops>, nl, p, ops, live.data(), nl, K, spos.data(), sdt.data(), count.data(),
                 offset.data(), v, stride, keep.data());
      compact(live.data(), nl, next.data());
      std::swap(live, next);
      cap = nl;
      st.field_samples += n_points;
      st.iterations += 1;
    }
  }

  void stream_march(RenderStats& st) {
    const int m = march_points_per_sample(p);
    const bool shadows = opt.mode == RenderMode::Shadow;
    march.resize(size_t(n_pixels));
    VNR_LAUNCH(march_begin_kernel, n_pixels, p, march.data(), keep.data());
    stream_pass(MarchOps{march.data(), m}, st);
    if (shadows) {
      shadow.resize(size_t(n_pixels));
      VNR_LAUNCH(shadow_begin_kernel, n_pixels, p, march.data(), shadow.data(), keep.data());
      stream_pass(ShadowOps{shadow.data()}, st);
    }
    VNR_LAUNCH(march_pixel_kernel, n_pixels, p, march.data(), shadows ? shadow.data() : nullptr, image.data());
  }

  void stream_path(RenderStats& st) {
    path.resize(size_t(n_pixels));
    VNR_LAUNCH(path_begin_kernel, n_pixels, p, path.data(), keep.data(), image.data());
    compact(all.data(), n_pixels, live.data());
    int64_t nl = read_counts(nullptr, nullptr, st);
    while (nl > 0) {
      const int64_t n_padded = cuda::round_up(nl, 16);
      ensure_points(n_padded);
      VNR_LAUNCH(path_coords_kernel, n_padded, p, path.data(), live.data(), nl, n_padded, xyz.data());
      int stride = 1;
      const float* v = evaluate(n_padded, &stride);
      VNR_LAUNCH(path_shade_kernel, nl, p, path.data(), live.data(), nl, v, stride, keep.data(), image.data());
      compact(live.data(), nl, next.data());
      std::swap(live, next);
      st.field_samples += nl;
      st.iterations += 1;
      nl = read_counts(nullptr, nullptr, st);
    }
  }

  template <class Field>
  void inshader(const Field& f, size_t smem, RenderStats& st) {
    VNR_CUDA_CHECK(cudaMemsetAsync(samples.data(), 0, sizeof(unsigned long long), sb.stream));
    const dim3 grid(unsigned((opt.width + kBlockW - 1) / kBlockW), unsigned((opt.height + kBlockH - 1) / kBlockH));
    const unsigned threads = kWarpsPerBlock * 32;
    if (opt.mode == RenderMode::PathTrace) {
      inshader_path<Field><<<grid, threads, smem, sb.stream>>>(p, f, image.data(), samples.data());
    } else {
      const int shadow = opt.mode == RenderMode::Shadow;
      if (march_points_per_sample(p) == 1)
        inshader_march<Field, 1><<<grid, threads, smem, sb.stream>>>(p, f, shadow, image.data(), samples.data());
      else
        inshader_march<Field, 7><<<grid, threads, smem, sb.stream>>>(p, f, shadow, image.data(), samples.data());
    }
    VNR_CUDA_LAUNCHED();
    VNR_CUDA_CHECK(cudaMemcpyAsync(&host->samples, samples.data(), sizeof(unsigned long long), cudaMemcpyDeviceToHost,
                                   sb.stream));
    VNR_CUDA_CHECK(cudaStreamSynchronize(sb.stream));
    st.host_syncs += 1;
    st.field_samples += int64_t(host->samples);
  }

  void render(uint32_t frame, RenderStats& st) {
    const auto t0 = std::chrono::steady_clock::now();
    p.frame = frame;
    if (opt.strategy == RenderStrategy::Streaming) {
      ensure_queues();
      if (opt.mode == RenderMode::PathTrace) stream_path(st);
      else stream_march(st);
      VNR_CUDA_CHECK(cudaStreamSynchronize(sb.stream));
      st.host_syncs += 1;
    } else if (dnet) {
      inshader(NetWarpRef{netf_device.data()}, netf.smem_bytes(), st);
    } else {
      inshader(GridWarpField{dvol}, 0, st);
    }
    st.frames += 1;
    st.rays += n_pixels;
    st.seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
};

GpuRenderer::GpuRenderer(const Field& field, Vec3f box, const MacroCells& mc, const TransferFunction& tf,
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

void GpuRenderer::set_camera(const Camera& cam) { set_render_camera(impl_->p, cam, impl_->opt); }

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
