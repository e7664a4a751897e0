// vnr view: the browser viewer (docs/VIEWER.md) — vnr::ViewerEngine behind the HTTP + WebSocket server
// of src/view/. Prints one URL line on stdout and serves until SIGINT or SIGTERM.
#include <pthread.h>
#include <signal.h>
#include <cstdio>
#include "cli.h"
#include "view/server.h"
#include "vnr/core/error.h"
#include "vnr/core/parallel.h"
#include "vnr/viewer.h"

namespace vnr::cli {

namespace {

struct ViewArgs {
  std::string input, ground_truth, config = "paper", device = "auto", save_dir, host = "127.0.0.1";
  int port = 8765, threads = 0;
  bool train = false;
  int64_t batch = 65536;
  uint32_t seed = 1337;
  VolumeArgs vol;
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
  view::ServerOptions options;
  options.host = a.host;
  options.port = a.port;
  view::ViewServer server(options);  // first: a busy port fails before the input is loaded
  ViewerSetup setup;
  setup.input = a.input;
  setup.ground_truth = a.ground_truth;
  setup.volume_options = a.vol.open();
  setup.config = a.config;
  setup.device = a.device;
  setup.save_dir = a.save_dir;
  setup.train = a.train;
  setup.batch = a.batch;
  setup.seed = a.seed;
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
  if (a.host != "127.0.0.1" && a.host != "::1")
    std::fprintf(stderr, "vnr view: note: listening on %s, reachable from other machines (token required)\n",
                 a.host.c_str());
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
  c->add_option("input", a->input, "volume (sidecar, raw, NRRD), model (.vnr, instantvnr BSON), scene or series")
      ->required();
  c->add_flag("--train", a->train, "start training at once (a volume input, or a model with --ground-truth)");
  c->add_option("--config", a->config, "network of a model trained from a volume: preset or tiny-cuda-nn JSON")
      ->capture_default_str();
  add_device_option(c, a->device);
  c->add_option("--port", a->port, "TCP port (0: any free port; the URL line names it)")
      ->check(CLI::Range(0, 65535))
      ->capture_default_str();
  c->add_option("--host", a->host, "address to listen on (0.0.0.0 exposes the viewer to the network)")
      ->capture_default_str();
  c->add_option("--save-dir", a->save_dir, "directory the page may save models into (default: saving is refused)");
  c->add_option("--ground-truth", a->ground_truth, "the volume of a model input (truth view, slices, training)");
  c->add_option("--batch", a->batch, "training samples per step")->capture_default_str();
  c->add_option("--seed", a->seed, "seed of the model's initial parameters and the training samples")
      ->capture_default_str();
  c->add_option("--threads", a->threads, "CPU threads (default: all cores)");
  a->vol.add(c);
  c->callback([a]() { serve(*a); });
}

}  // namespace vnr::cli
