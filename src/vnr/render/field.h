#pragma once
// The one batched field query every integrator reads: normalised coordinates in [0,1)^3 in,
// normalised values out. It serves the ground-truth grid and a trained network alike, so every
// integrator and both execution strategies work on either.
#include <cstdint>
#include <memory>
#include "vnr/core/hd.h"
#include "vnr/nn/network.h"
#include "vnr/nn/point_eval.h"
#include "vnr/volume/volume.h"

namespace vnr {

class Field {
public:
  virtual ~Field() = default;
  virtual Int3 dims() const = 0;
  virtual const char* kind() const = 0;  // "grid" or "network"
  // Batched query (parallel inside): out[i] = field(x[i], y[i], z[i]).
  virtual void query(const float* x, const float* y, const float* z, int64_t n, float* out) const = 0;
};

// Point evaluation for the in-shader strategy (one sample at a time inside a ray's loop).
struct GridPointFn {
  GridView g;
  VNR_HD VNR_INLINE float operator()(float x, float y, float z) const { return grid_lookup(g, x, y, z); }
};

class GridField final : public Field {
public:
  explicit GridField(GridView g) : g_(g) {}
  Int3 dims() const override { return Int3{g_.nx, g_.ny, g_.nz}; }
  const char* kind() const override { return "grid"; }
  void query(const float* x, const float* y, const float* z, int64_t n, float* out) const override;
  GridPointFn point_fn() const { return GridPointFn{g_}; }
  const GridView& view() const { return g_; }

private:
  GridView g_;
};

struct NetworkPointFn {
  const PointEvaluator* eval;
  float operator()(float x, float y, float z) const { return eval->eval(x, y, z); }
};

class NetworkField final : public Field {
public:
  NetworkField(const Network& net, Int3 dims) : net_(net), dims_(dims), point_(net) {}
  Int3 dims() const override { return dims_; }
  const char* kind() const override { return "network"; }
  void query(const float* x, const float* y, const float* z, int64_t n, float* out) const override;
  NetworkPointFn point_fn() const { return NetworkPointFn{&point_}; }
  const Network& network() const { return net_; }

private:
  const Network& net_;
  Int3 dims_;
  PointEvaluator point_;
};

}  // namespace vnr
