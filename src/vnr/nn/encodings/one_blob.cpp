// OneBlob encoding (docs/semantics.md A.3.3): per axis, n_bins integrals of a quartic kernel centred on
// x over the bins of the periodic unit interval; parameter-free.
#include <algorithm>
#include "vnr/error.h"
#include "vnr/math.h"
#include "vnr/nn/encoding.h"
#include "vnr/nn/json_get.h"

namespace vnr {
namespace {

// The quartic kernel's CDF and its derivative in t.
float oneblob_q(float t, float n) {
  float u = t * n;
  float v = (15.0f / 16.0f) * u * (1.0f - (2.0f / 3.0f) * u * u + (1.0f / 5.0f) * u * u * u * u) + 0.5f;
  return clampf(v, 0.0f, 1.0f);
}
float oneblob_dq(float t, float n) {
  float u = t * n;
  if (u <= -1.0f || u >= 1.0f) return 0.0f;
  float a = 1.0f - u * u;
  return (15.0f / 16.0f) * n * a * a;
}

class OneBlobEncoding final : public Encoding {
public:
  explicit OneBlobEncoding(uint32_t n_bins) : nb_(n_bins) {}
  uint32_t output_width() const override { return 3 * nb_; }
  uint32_t min_alignment() const override { return nb_; }

  void forward(const float* x, const float* y, const float* z, int n, const uint16_t*, float* X0) const override {
    float buf[kMaxParameterFreeWidth];
    for (int s = 0; s < n; ++s) {
      const float p[3] = {x[s], y[s], z[s]};
      encode_point(p, nullptr, buf);
      for (uint32_t j = 0; j < 3 * nb_; ++j) X0[size_t(j) * n + s] = buf[j];
    }
  }
  void encode_point(const float xyz[3], const uint16_t*, float* out) const override {
    const float fn = float(nb_);
    for (uint32_t d = 0; d < 3; ++d) {
      auto C = [&](uint32_t b) {
        float t = float(b) / fn - xyz[d];
        return oneblob_q(t, fn) + oneblob_q(t - 1.0f, fn) + oneblob_q(t + 1.0f, fn);
      };
      for (uint32_t b = 0; b < nb_; ++b) out[d * nb_ + b] = b + 1 < nb_ ? C(b + 1) - C(b) : C(0) + 1.0f - C(nb_ - 1);
    }
  }
  void encode_point_input_grad(const float xyz[3], const uint16_t*, float* jac) const override {
    std::fill(jac, jac + size_t(output_width()) * 3, 0.0f);
    const float fn = float(nb_);
    for (uint32_t d = 0; d < 3; ++d) {
      auto dC = [&](uint32_t b) {  // d C(b) / d x
        float t = float(b) / fn - xyz[d];
        return -(oneblob_dq(t, fn) + oneblob_dq(t - 1.0f, fn) + oneblob_dq(t + 1.0f, fn));
      };
      for (uint32_t b = 0; b < nb_; ++b)
        jac[(d * nb_ + b) * 3 + d] = b + 1 < nb_ ? dC(b + 1) - dC(b) : dC(0) - dC(nb_ - 1);
    }
  }
  Json to_json() const override { return {{"otype", "OneBlob"}, {"n_bins", nb_}}; }

private:
  uint32_t nb_;
};

void parse_one_blob(const std::string&, const Json& j, EncodingConfig& e) {
  e.type = EncodingType::OneBlob;
  e.n_bins = json_get<uint32_t>(j, "n_bins", 16u, "encoding");
  if (e.n_bins < 1 || e.n_bins > kMaxOneBlobBins || (e.n_bins & (e.n_bins - 1)))
    fail("encoding: n_bins must be a power of two in 1..{}, got {}", kMaxOneBlobBins, e.n_bins);
}

}  // namespace
}  // namespace vnr

VNR_ENCODING_REGISTRAR(one_blob) {
  registry.add({"OneBlob", {"OneBlob"}, 20, parse_one_blob, [](const EncodingConfig& e) -> std::unique_ptr<Encoding> {
                  return std::make_unique<OneBlobEncoding>(e.n_bins);
                }});
}
