// vnr view: the browser viewer (docs/VIEWER.md) — vnr::ViewerEngine behind the HTTP + WebSocket server
// of src/view/. Prints one URL line on stdout and serves until SIGINT or SIGTERM.
#include <pthread.h>
#include <signal.h>
#include <cstdio>
#include "cli.h"
#include "view/server.h"
#include "vnr/error.h"
#include "vnr/threads.h"
#include "vnr/renderer.h"
#include "vnr/viewer.h"

namespace vnr::cli {

namespace {

// The options fill the engine's setup and the server's options directly (their defaults are the CLI's).
struct ViewArgs {
  ViewerSetup setup;  // but volume_options: from vol
  view::ServerOptions server;
  int threads = 0;
  VolumeArgs vol;
  std::string cache_budget = "auto", cache_dims;
};

// Blocked in every thread (the engine's and the server's inherit the mask), taken by sigwait in main:
// no code runs in a signal handler.
sigset_t stop_signals() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  return set;
}

void serve(const ViewArgs& a) {
  const sigset_t signals = stop_signals();
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  set_num_threads(a.threads);
  view::ViewServer server(a.server);  // first: a busy port fails before the input is loaded
  ViewerSetup setup = a.setup;
  setup.volume_options = a.vol.open();
  setup.cache_budget = parse_cache_budget(a.cache_budget);
  if (!a.cache_dims.empty()) setup.cache_dims = parse_dims(a.cache_dims, "--cache-dims");
  ViewerEngine engine(setup);
  // Whatever happens below, the server's threads end before the engine they use is destroyed.
  struct StopServerFirst {
    view::ViewServer& server;
    ~StopServerFirst() { server.stop(); }
  } stop_server_first{server};
  server.start(engine);
  std::printf("vnr view: %s\n", server.url().c_str());
  std::fflush(stdout);
  const ViewerInfo& info = engine.info();
  std::fprintf(stderr, "vnr view: %s on %s; Ctrl-C stops\n", info.description.c_str(), info.device.c_str());
  if (a.server.host != "127.0.0.1" && a.server.host != "::1")
    std::fprintf(stderr, "vnr view: note: listening on %s, reachable from other machines (token required)\n",
                 a.server.host.c_str());
  int sig = 0;
  sigwait(&signals, &sig);
  server.stop();
  engine.stop();
  std::fprintf(stderr, "vnr view: stopped\n");
}

}  // namespace

void add_view(CLI::App& app) {
  auto a = std::make_shared<ViewArgs>();
  CLI::App* c = app.add_subcommand("view", "serve an interactive viewer (training and rendering) to a web browser");
  c->add_option("input", a->setup.input, "volume (sidecar, raw, NRRD), model (.vnr, instantvnr BSON), scene or series")
      ->required();
  c->add_flag("--train", a->setup.train, "start training at once (a volume input, or a model with --ground-truth)");
  c->add_option("--config", a->setup.config, "network of a model trained from a volume: preset or tiny-cuda-nn JSON")
      ->capture_default_str();
  add_device_option(c, a->setup.device);
  c->add_option("--port", a->server.port, "TCP port (0: any free port; the URL line names it)")
      ->check(CLI::Range(0, 65535))
      ->capture_default_str();
  c->add_option("--host", a->server.host, "address to listen on (0.0.0.0 exposes the viewer to the network)")
      ->capture_default_str();
  c->add_option("--save-dir", a->setup.save_dir, "directory the page may save models into (default: saving is refused)");
  c->add_option("--ground-truth", a->setup.ground_truth, "the volume of a model input (truth view, slices, training)");
  c->add_option("--batch", a->setup.batch, "training samples per step")->capture_default_str();
  c->add_option("--seed", a->setup.seed, "seed of the model's initial parameters and the training samples")
      ->capture_default_str();
  c->add_option("--threads", a->threads, "CPU threads (default: all cores)");
  c->add_option("--cache-budget", a->cache_budget,
                "memory of the brick cache a model renders from, e.g. 512MiB (auto: a quarter of the available "
                "memory, at most 4 GiB)")
      ->capture_default_str();
  c->add_option("--cache-dims", a->cache_dims,
                "X,Y,Z: the voxels the cache decodes a model at (default: the model's dims; any size, e.g. "
                "4096,4096,4096)");
  a->vol.add(c);
  c->callback([a]() { serve(*a); });
}

}  // namespace vnr::cli
