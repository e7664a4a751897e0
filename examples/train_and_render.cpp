// vnr as a library, start to finish: open a volume, train a network on it, print its PSNR and
// compression ratio, render the network to a PNG and save the model.
//
//   example_train_and_render [VOLUME [OUT_DIR [STEPS]]]
//
// VOLUME is any file `vnr train` reads (JSON sidecar, instantvnr scene, NRRD); without one (or with an
// empty VOLUME argument) the program makes a 64^3 Marschner-Lobb volume in memory. Build it against an
// installed vnr with find_package(vnr) and target_link_libraries(app vnr::vnr).
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>
#include "vnr/vnr.h"

// The Marschner-Lobb test signal (alpha 0.25, f_M 6) at voxel centres of an n^3 grid.
vnr::Volume marschner_lobb(int n) {
  const double pi = 3.14159265358979323846;
  std::vector<float> values(size_t(n) * n * n);
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const double px = 2 * (x + 0.5) / n - 1, py = 2 * (y + 0.5) / n - 1, pz = 2 * (z + 0.5) / n - 1;
        const double r = std::sqrt(px * px + py * py);
        const double rho = std::cos(2 * pi * 6 * std::cos(pi * r / 2));
        values[(size_t(z) * n + y) * n + x] = float((1 - std::sin(pi * pz / 2) + 0.25 * (1 + rho)) / 2.5);
      }
  return vnr::volume_from_array(values.data(), vnr::Int3{n, n, n});
}

int main(int argc, char** argv) {
  const std::string out_dir = argc > 2 ? argv[2] : ".";
  const int64_t steps = argc > 3 ? std::atoll(argv[3]) : 300;
  try {
    vnr::Volume volume = argc > 1 && *argv[1] ? vnr::open_volume(argv[1]) : marschner_lobb(64);

    // A network of the "small" preset (any preset name or tiny-cuda-nn JSON file works), trained on the
    // CPU; Device::Cuda trains on a GPU when one is visible (vnr::cuda::resolve_device("auto") picks).
    vnr::Model model = vnr::create_model(vnr::load_config("small"), volume, /*seed=*/1);
    vnr::TrainOptions options;
    options.batch = 1 << 16;
    auto session = vnr::make_training_session(model, volume, vnr::Device::Cpu, options);
    session->add_step_callback([&](const vnr::TrainingProgress& p) {
      if (p.step % 100 == 0) std::printf("step %lld  loss %.5f  %.1f M samples/s\n", (long long)p.step, p.loss,
                                         p.samples_per_second / 1e6);
    });
    session->run(steps);
    session->finish();  // the trained parameters and the online macro-cells into the model

    const vnr::EvalResult eval = vnr::evaluate_model(model, volume);
    std::printf("PSNR %.2f dB, SSIM %.4f, compression ratio %.1f\n", eval.psnr, eval.ssim,
                vnr::compression_ratio(model));

    vnr::Renderer renderer(model, vnr::Device::Cpu);
    renderer.set_size(256, 256);
    renderer.set_transfer_function("cool-warm");
    renderer.set_camera(vnr::orbit_camera(renderer.box(), 30, 20, 30));
    for (int frame = 0; frame < 4; ++frame) renderer.render_frame();  // accumulates 4 jittered frames
    renderer.save(out_dir + "/example.png");
    vnr::save_model(out_dir + "/example.vnr", model);
    std::printf("wrote %s/example.png and %s/example.vnr\n", out_dir.c_str(), out_dir.c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}
