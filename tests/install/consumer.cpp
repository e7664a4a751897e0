// Builds against the installed vnr: a volume from an array, a model of it, one rendered frame.
#include <cstdio>
#include <vector>
#include <vnr/vnr.h>

int main() {
  const vnr::Int3 dims{8, 8, 8};
  std::vector<float> values(dims.count());
  for (size_t i = 0; i < values.size(); ++i) values[i] = float(i % 17);
  vnr::Volume volume = vnr::volume_from_array(values.data(), dims);
  vnr::Model model = vnr::create_model(vnr::ModelConfig::from_json(vnr::preset_config("tiny")), volume);
  vnr::Renderer renderer(volume, vnr::Device::Cpu);
  renderer.set_size(16, 16);
  renderer.render_frame();
  std::printf("vnr %s: %lld parameters, %dx%d image\n", vnr::version(), (long long)model.n_params(),
              renderer.image().width, renderer.image().height);
  return renderer.frames() == 1 ? 0 : 1;
}
