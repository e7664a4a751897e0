// Identity encoding (docs/semantics.md A.3.1): x * scale + offset per axis, parameter-free.
#include <algorithm>
#include "vnr/nn/encoding.h"
#include "vnr/nn/json_get.h"

namespace vnr {
namespace {

class IdentityEncoding final : public Encoding {
public:
  IdentityEncoding(float scale, float offset) : scale_(scale), offset_(offset) {}
  uint32_t output_width() const override { return 3; }

  void forward(const float* x, const float* y, const float* z, int n, const uint16_t*, float* X0) const override {
    const float* axes[3] = {x, y, z};
    for (int d = 0; d < 3; ++d)
      for (int s = 0; s < n; ++s) X0[size_t(d) * n + s] = axes[d][s] * scale_ + offset_;
  }
  void encode_point(const float xyz[3], const uint16_t*, float* out) const override {
    for (int d = 0; d < 3; ++d) out[d] = xyz[d] * scale_ + offset_;
  }
  void encode_point_input_grad(const float*, const uint16_t*, float* jac) const override {
    std::fill(jac, jac + 9, 0.0f);
    for (int d = 0; d < 3; ++d) jac[d * 3 + d] = scale_;
  }
  Json to_json() const override { return {{"otype", "Identity"}, {"scale", scale_}, {"offset", offset_}}; }

private:
  float scale_, offset_;
};

void parse_identity(const std::string&, const Json& j, EncodingConfig& e) {
  e.type = EncodingType::Identity;
  e.scale = json_get<float>(j, "scale", 1.0f, "encoding");
  e.offset = json_get<float>(j, "offset", 0.0f, "encoding");
}

}  // namespace
}  // namespace vnr

VNR_ENCODING_REGISTRAR(identity) {
  registry.add({"Identity", {"Identity"}, 30, parse_identity, [](const EncodingConfig& e) -> std::unique_ptr<Encoding> {
                  return std::make_unique<IdentityEncoding>(e.scale, e.offset);
                }});
}
