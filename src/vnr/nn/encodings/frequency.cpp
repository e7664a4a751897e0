// Frequency encoding (docs/semantics.md A.3.2): sin and cos of 2^k pi x per axis, parameter-free.
#include <cmath>
#include "vnr/error.h"
#include "vnr/nn/encoding.h"
#include "vnr/nn/json_get.h"

namespace vnr {
namespace {

constexpr float kPi = 3.14159265358979323846f;

class FrequencyEncoding final : public Encoding {
public:
  explicit FrequencyEncoding(uint32_t n_frequencies) : nf_(n_frequencies) {}
  uint32_t output_width() const override { return 3 * 2 * nf_; }

  void forward(const float* x, const float* y, const float* z, int n, const uint16_t*, float* X0) const override {
    for (int s = 0; s < n; ++s) {
      const float p[3] = {x[s], y[s], z[s]};
      for (uint32_t j = 0; j < 3 * 2 * nf_; ++j) X0[size_t(j) * n + s] = value(p, j);
    }
  }
  void encode_point(const float xyz[3], const uint16_t*, float* out) const override {
    for (uint32_t j = 0; j < 3 * 2 * nf_; ++j) out[j] = value(xyz, j);
  }
  void encode_point_input_grad(const float xyz[3], const uint16_t*, float* jac) const override {
    std::fill(jac, jac + size_t(output_width()) * 3, 0.0f);
    for (uint32_t j = 0; j < 3 * 2 * nf_; ++j) {
      uint32_t d = j / (2 * nf_), k = (j / 2) % nf_;
      float a = std::ldexp(1.0f, int(k)) * kPi;
      jac[j * 3 + d] = (j & 1) ? -a * std::sin(a * xyz[d]) : a * std::cos(a * xyz[d]);
    }
  }
  Json to_json() const override { return {{"otype", "Frequency"}, {"n_frequencies", nf_}}; }

private:
  // Feature j: axis j / (2 nf), frequency (j / 2) % nf, odd j the cosine (as tcnn: sin(arg + pi/2)).
  float value(const float xyz[3], uint32_t j) const {
    uint32_t d = j / (2 * nf_), k = (j / 2) % nf_;
    float arg = std::ldexp(1.0f, int(k)) * kPi * xyz[d];
    return (j & 1) ? std::sin(arg + kPi / 2) : std::sin(arg);
  }
  uint32_t nf_;
};

void parse_frequency(const std::string&, const Json& j, EncodingConfig& e) {
  e.type = EncodingType::Frequency;
  e.n_frequencies = json_get<uint32_t>(j, "n_frequencies", 12u, "encoding");
  if (e.n_frequencies < 1 || e.n_frequencies > kMaxFrequencies)
    fail("encoding: n_frequencies must be in 1..{}, got {}", kMaxFrequencies, e.n_frequencies);
}

}  // namespace
}  // namespace vnr

VNR_ENCODING_REGISTRAR(frequency) {
  registry.add({"Frequency", {"Frequency"}, 10, parse_frequency, [](const EncodingConfig& e) -> std::unique_ptr<Encoding> {
                  return std::make_unique<FrequencyEncoding>(e.n_frequencies);
                }});
}
