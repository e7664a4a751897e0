#pragma once
// The sample-streaming wavefront, written once for every backend: the order of the stages of
// stream_stages.h and the queue bookkeeping between them, over a backend B that owns the buffers and
// knows how to run a stage, scan, compact and query (CpuStreamBackend in renderer.cpp: host vectors
// and OpenMP; the GPU renderer's: GPU memory, CUB and one host synchronisation per iteration).
//
// B provides (pointers stay valid until the next call that resizes):
//   run(n, stage)                  the per-slot stage over [0, n)
//   march_states(n), shadow_states(n), path_states(n), pixel_keep(n)
//                                  per-pixel state arrays and keep flags for n pixels
//   start_queue() -> cap           live = the keep-flagged pixels; an upper bound of their count
//   live_count(st) -> n            the exact live count (a GPU waits for it)
//   live(), n_live(), keep()       the live queue, where its length is, the per-slot keep flags
//   slots(cap, K)                  count/offset for cap + 1 slots, positions and steps for cap * K
//   spos(), sdt(), count(), offset()
//   scan(cap, &total, st) -> n     offsets of count[0, cap], their total; the exact live count
//   points(n) -> PointSink         packed query buffers for n points
//   query(n, &stride, st) -> v     the field at the n packed points (value q at v[q * stride])
//   compact(n) -> cap              live = the slots r < n whose keep flag is set, in order; an upper
//                                  bound of their count (exact where known: the next coordinate stage
//                                  runs over it, and a static schedule splits it evenly only then)
#include <cstdint>
#include "vnr/render/renderer.h"
#include "vnr/render/stream_stages.h"

namespace vnr {

// One pass (primary or shadow rays) over the keep-flagged pixels: each iteration up to K samples per
// live ray, one batched query, shading, compaction.
template <class B, class Ops>
void stream_pass(B& b, const RenderParams& p, const Ops& ops, int K, RenderStats& st) {
  int64_t cap = b.start_queue();  // an upper bound of the live rays
  for (;;) {
    b.slots(cap, K);
    b.run(cap + 1, StreamNext<Ops>{p, ops, b.live(), b.n_live(), K, b.spos(), b.sdt(), b.count()});
    int64_t n_samples = 0;
    const int64_t nl = b.scan(cap, &n_samples, st);
    if (nl == 0) break;
    const int64_t n_points = n_samples * ops.m;
    b.run(nl, StreamEmit<Ops>{p, ops, K, b.spos(), b.count(), b.offset(), b.points(n_points)});
    int stride = 1;
    const float* v = b.query(n_points, &stride, st);  // one batched inference per iteration
    b.run(nl, StreamShade<Ops>{p, ops, b.live(), K, b.spos(), b.sdt(), b.count(), b.offset(), v, stride, b.keep()});
    cap = b.compact(nl);
    st.field_samples += n_points;
    st.iterations += 1;
  }
}

// A ray-marched frame (+ the shadow pass when `shadows`) into img (n pixels of p.cam).
template <class B>
void stream_march_frame(B& b, const RenderParams& p, bool shadows, int K, Vec4f* img, RenderStats& st) {
  const int64_t n = int64_t(p.cam.width) * p.cam.height;
  MarchState* march = b.march_states(n);
  b.run(n, MarchBeginStage{p, march, b.pixel_keep(n)});
  stream_pass(b, p, MarchOps{march, march_points_per_sample(p)}, K, st);
  ShadowState* shadow = nullptr;
  if (shadows) {  // second pass: one shadow ray per pixel from its highest-contribution sample
    shadow = b.shadow_states(n);
    b.run(n, ShadowBeginStage{p, march, shadow, b.pixel_keep(n)});
    stream_pass(b, p, ShadowOps{shadow}, K, st);
  }
  b.run(n, MarchPixelStage{p, march, shadow, img});
}

// A path-traced frame into img: one field point per live path per iteration.
template <class B>
void stream_path_frame(B& b, const RenderParams& p, Vec4f* img, RenderStats& st) {
  const int64_t n = int64_t(p.cam.width) * p.cam.height;
  PathState* path = b.path_states(n);
  b.run(n, PathBeginStage{p, path, b.pixel_keep(n), img});
  b.start_queue();
  for (int64_t nl = b.live_count(st); nl > 0; nl = b.live_count(st)) {
    b.run(nl, PathCoords{p, path, b.live(), nl, b.points(nl)});
    int stride = 1;
    const float* v = b.query(nl, &stride, st);
    b.run(nl, PathShade{p, path, b.live(), v, stride, b.keep(), img});
    b.compact(nl);
    st.field_samples += nl;
    st.iterations += 1;
  }
}

}  // namespace vnr
