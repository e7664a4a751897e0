// The server's life cycle: listening socket, network thread, broadcaster thread, worker.
#include "view/server.h"
#include "view/access.h"
#include "view/protocol.h"
#include "view/server_core.h"
#include "vnr/error.h"

namespace vnr::view {

// ---- Worker ------------------------------------------------------------------------------------------

Worker::Worker() {
  thread_ = std::thread([this] {
    while (true) {
      std::function<void()> task;
      {
        std::unique_lock lk(mu_);
        cv_.wait(lk, [&] { return stopping_ || !tasks_.empty(); });
        if (stopping_) return;
        task = std::move(tasks_.front());
        tasks_.pop_front();
      }
      task();
    }
  });
}

Worker::~Worker() { stop(); }

bool Worker::post(std::function<void()> task) {
  {
    std::lock_guard lk(mu_);
    if (stopping_ || tasks_.size() >= 16) return false;
    tasks_.push_back(std::move(task));
  }
  cv_.notify_one();
  return true;
}

void Worker::stop() {
  {
    std::lock_guard lk(mu_);
    stopping_ = true;
    tasks_.clear();
  }
  cv_.notify_one();
  if (thread_.joinable()) thread_.join();
}

// ---- ServerCore -----------------------------------------------------------------------------------------

void ServerCore::add_session(const std::shared_ptr<WsSession>& s) {
  std::lock_guard lk(sessions_mu);
  sessions.push_back(s);
}

void ServerCore::remove_session(const WsSession* s) {
  std::lock_guard lk(sessions_mu);
  std::erase_if(sessions, [&](const std::weak_ptr<WsSession>& w) {
    auto p = w.lock();
    return !p || p.get() == s;
  });
}

std::vector<std::shared_ptr<WsSession>> ServerCore::live_sessions() {
  std::lock_guard lk(sessions_mu);
  std::vector<std::shared_ptr<WsSession>> out;
  for (auto& w : sessions)
    if (auto p = w.lock()) out.push_back(std::move(p));
  return out;
}

// ---- ViewServer -----------------------------------------------------------------------------------------

struct ViewServer::Impl {
  ServerOptions options;
  ServerCore core;
  tcp::acceptor acceptor{core.ioc};
  int port = 0;
  std::thread io_thread, broadcaster;
  std::atomic<bool> stopping{false};
  bool started = false, stopped = false;

  void accept() {
    acceptor.async_accept([this](beast::error_code ec, tcp::socket socket) {
      if (!acceptor.is_open()) return;
      if (!ec) start_http_session(std::move(socket), core);
      accept();  // errors such as too many open files: keep serving the connections we have
    });
  }
};

ViewServer::ViewServer(ServerOptions options) : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.options = std::move(options);
  if (m.options.port < 0 || m.options.port > 65535) fail("--port must be in 0..65535, got {}", m.options.port);
  m.core.token = m.options.token.empty() ? make_token() : m.options.token;
  m.core.send_buffer_bytes = m.options.send_buffer_bytes;
  beast::error_code ec;
  const net::ip::address address = net::ip::make_address(m.options.host, ec);
  if (ec) fail("--host '{}' is not an IP address", m.options.host);
  const tcp::endpoint endpoint(address, uint16_t(m.options.port));
  const std::string where = m.options.host + ":" + std::to_string(m.options.port);
  m.acceptor.open(endpoint.protocol(), ec);
  if (!ec) m.acceptor.set_option(net::socket_base::reuse_address(true), ec);
  if (!ec) m.acceptor.bind(endpoint, ec);
  if (!ec) m.acceptor.listen(net::socket_base::max_listen_connections, ec);
  if (ec) fail("cannot listen on {}: {}", where, ec.message());
  m.port = m.acceptor.local_endpoint().port();
}

ViewServer::~ViewServer() { stop(); }

int ViewServer::port() const { return impl_->port; }
const std::string& ViewServer::token() const { return impl_->core.token; }

std::string ViewServer::url() const {
  const bool v6 = impl_->options.host.find(':') != std::string::npos;
  const std::string host = v6 ? "[" + impl_->options.host + "]" : impl_->options.host;
  return "http://" + host + ":" + std::to_string(impl_->port) + "/?token=" + impl_->core.token;
}

void ViewServer::start(ViewerEngine& engine) {
  Impl& m = *impl_;
  if (m.started) fail("the viewer server is already started");
  m.started = true;
  m.core.engine = &engine;
  m.core.histogram = engine.histogram(256);
  m.accept();
  m.io_thread = std::thread([&m] { m.core.ioc.run(); });
  m.broadcaster = std::thread([&m] { run_broadcaster(m.core, m.stopping); });
}

void ViewServer::stop() {
  Impl& m = *impl_;
  if (m.stopped) return;
  m.stopped = true;
  m.stopping = true;
  if (m.broadcaster.joinable()) m.broadcaster.join();
  if (m.io_thread.joinable()) {
    net::post(m.core.ioc, [&m] {
      beast::error_code ec;
      m.acceptor.close(ec);
      for (auto& s : m.core.live_sessions()) s->close();
    });
    // Let the closes go out, then end the loop; what is left is dropped with the io_context.
    net::post(m.core.ioc, [&m] { m.core.ioc.stop(); });
    m.io_thread.join();
  }
  m.core.worker.stop();
}

ServerStats ViewServer::stats() const {
  ServerCore& c = impl_->core;
  ServerStats s;
  s.frames_encoded = c.frames_encoded;
  s.images_encoded = c.images_encoded;
  s.encode_seconds = double(c.encode_ns) * 1e-9;
  s.broadcast_seconds = double(c.broadcast_ns) * 1e-9;
  s.messages_sent = c.messages_sent;
  s.frames_dropped = c.frames_dropped;
  s.sessions = c.live_sessions().size();
  return s;
}

}  // namespace vnr::view
