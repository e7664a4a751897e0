#pragma once
// Internal to the server: what the listener, the HTTP and WebSocket sessions and the broadcaster share.
#include <atomic>
#include <utility>  // before Asio: Boost 1.74's awaitable.hpp uses std::exchange without it
#include <boost/asio.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <condition_variable>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>
#include "view/server.h"

namespace vnr::view {

namespace net = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = net::ip::tcp;

inline std::string_view to_sv(beast::string_view s) { return {s.data(), s.size()}; }

constexpr size_t kRequestHeadLimit = 8 * 1024;
constexpr size_t kMessageLimit = 1024 * 1024;
constexpr size_t kMaxQueuedTexts = 256;  // replies a client has not read yet: beyond this it is closed

// One thread for work that may take long (a screenshot waits for a refined frame; saving a model),
// so the network thread never waits on the engine.
class Worker {
public:
  Worker();
  ~Worker();  // stop()
  // false when the queue is full (the caller answers "busy") or the worker is stopped.
  bool post(std::function<void()> task);
  void stop();  // finishes the running task, drops the rest, joins

private:
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<std::function<void()>> tasks_;
  bool stopping_ = false;
  std::thread thread_;
};

// A frame's images as ready-to-send binary messages, shared by every session.
struct EncodedFrame {
  std::vector<std::string> messages;
};

class WsSession;

struct ServerCore {
  net::io_context ioc{1};
  ViewerEngine* engine = nullptr;
  std::string token;
  int send_buffer_bytes = 0;
  Worker worker;
  std::vector<uint32_t> histogram;  // for hello: computed once at start

  std::mutex sessions_mu;
  std::vector<std::weak_ptr<WsSession>> sessions;
  std::shared_ptr<const EncodedFrame> latest_frame;  // under sessions_mu: what a new session shows first

  std::atomic<uint64_t> frames_encoded{0}, images_encoded{0}, messages_sent{0}, frames_dropped{0};
  std::atomic<uint64_t> encode_ns{0}, broadcast_ns{0};

  void add_session(const std::shared_ptr<WsSession>& s);
  void remove_session(const WsSession* s);
  std::vector<std::shared_ptr<WsSession>> live_sessions();
};

class WsSession : public std::enable_shared_from_this<WsSession> {
public:
  WsSession(tcp::socket&& socket, ServerCore& core);
  // Completes the upgrade of `req`, sends hello and the latest frame, then reads messages.
  void start(http::request<http::empty_body> req);
  // From any thread (each posts to the network thread).
  void send_text(std::string message);
  void send_state(std::shared_ptr<const std::string> message);  // replaces an unsent state message
  void send_frame(std::shared_ptr<const EncodedFrame> frame);   // replaces an unsent frame
  void send_losses(std::string message);                         // losses_busy until written
  void close();

  // The broadcaster's bookkeeping of this client's losses (touched by the broadcaster thread only,
  // except losses_busy).
  size_t losses_sent = 0;
  std::atomic<bool> losses_busy{false};

private:
  void read();
  void on_message(beast::error_code ec);
  void pump();  // starts the next write when none is in flight
  void write(const std::string& bytes, bool binary);
  void fail_and_close();

  websocket::stream<beast::tcp_stream> ws_;
  ServerCore& core_;
  beast::flat_buffer in_;
  bool open_ = false, writing_ = false;
  // Outgoing, by priority: replies and losses, then the newest state, then frames.
  struct Text {
    std::string bytes;
    bool losses = false;
  };
  std::deque<Text> texts_;
  Text writing_text_;
  std::shared_ptr<const std::string> state_, writing_state_;
  std::shared_ptr<const EncodedFrame> next_frame_, frame_;  // the newest unsent; the one being sent
  size_t frame_index_ = 0;                                   // next image message of frame_
};

// The listener's sessions for plain HTTP requests (and the upgrade to a WebSocket).
void start_http_session(tcp::socket&& socket, ServerCore& core);

// The broadcaster thread's loop: frames, state and losses to every session until `stop`.
void run_broadcaster(ServerCore& core, const std::atomic<bool>& stop);

}  // namespace vnr::view
