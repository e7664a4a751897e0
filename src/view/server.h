#pragma once
// The `vnr view` server (docs/VIEWER.md): HTTP for the embedded page, /screenshot.png, /scene.json and
// /tf.json, and a WebSocket per browser tab that carries settings in and state, losses and JPEG frames
// out. One network thread serves every socket; one broadcaster thread takes the engine's frames,
// encodes each image once and hands it to every session, where a newer frame replaces one that is not
// yet being sent (a slow client sees fewer frames; nothing queues up). Slow requests (a screenshot
// waits for a refined frame, saving writes a file) run on a worker thread.
#include <cstdint>
#include <memory>
#include <string>
#include "vnr/viewer.h"

namespace vnr::view {

struct ServerOptions {
  std::string host = "127.0.0.1";
  int port = 8765;      // 0: any free port
  std::string token;    // "" = a fresh make_token()
  // Kernel send buffer of each WebSocket: small enough that a slow client's writes stall soon (and its
  // frames are dropped) instead of megabytes of stale frames piling up in the socket.
  int send_buffer_bytes = 256 * 1024;
};

struct ServerStats {
  uint64_t frames_encoded = 0;    // engine frames turned into JPEG messages
  uint64_t images_encoded = 0;
  double encode_seconds = 0;      // JPEG encoding, all images
  double broadcast_seconds = 0;   // per frame: encoding + headers + handing to sessions
  uint64_t messages_sent = 0;     // binary frame messages written to sockets
  uint64_t frames_dropped = 0;    // replaced before a session started sending them
  size_t sessions = 0;            // open WebSockets now
};

class ViewServer {
public:
  // Binds and listens (vnr::Error naming the address when it cannot, e.g. the port is in use); no
  // connection is served before start().
  explicit ViewServer(ServerOptions options);
  ~ViewServer();  // stop()
  ViewServer(const ViewServer&) = delete;
  ViewServer& operator=(const ViewServer&) = delete;

  int port() const;
  const std::string& token() const;
  std::string url() const;  // http://HOST:PORT/?token=TOKEN

  // Serves `engine` (which must outlive the server or its stop()) on the server's threads.
  void start(ViewerEngine& engine);
  // Stops accepting, closes every socket, ends the threads; idempotent. The engine keeps running.
  void stop();
  ServerStats stats() const;

private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace vnr::view
