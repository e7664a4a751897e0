#pragma once
// The per-sample side of transfer functions (vnr/transfer_function.h): the POD view and its lookup.
#include "vnr/hd.h"
#include "vnr/math.h"
#include "vnr/transfer_function.h"

namespace vnr {

// POD view for per-sample code.
struct TfView {
  const Vec4f* table = nullptr;
  int n = 0;
  float lo = 0, scale = 1;  // u -> (u - lo) * scale in [0,1]
};
inline TfView view_of(const TransferFunction& tf) {
  float w = tf.hi - tf.lo;
  return TfView{tf.table.data(), int(tf.table.size()), tf.lo, w > 0 ? 1.0f / w : 0.0f};
}

VNR_HD VNR_INLINE Vec4f tf_lookup(const TfView& tf, float u) {
  float x = clampf((u - tf.lo) * tf.scale, 0.0f, 1.0f) * float(tf.n - 1);
  int i = int(x);
  if (i > tf.n - 2) i = tf.n - 2;
  float t = x - float(i);
  const Vec4f a = tf.table[i], b = tf.table[i + 1];
  return Vec4f{a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t, a.z + (b.z - a.z) * t, a.w + (b.w - a.w) * t};
}

}  // namespace vnr
