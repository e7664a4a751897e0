// A small Boost.Beast client for the viewer server's tests: plain HTTP GETs and a WebSocket client
// whose reads have timeouts (messages are read in the background while its io_context runs).
#pragma once
#include <utility>  // before Asio: Boost 1.74's awaitable.hpp uses std::exchange without it
#include <boost/asio.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <chrono>
#include <deque>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace vnr::test {

namespace net = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = net::ip::tcp;

struct HttpReply {
  int status = 0;
  std::string body;
  http::response<http::string_body> res;
};

// One GET (or another method) on a fresh connection, with extra headers.
inline HttpReply http_request(int port, const std::string& target, const std::string& cookie = "",
                              http::verb method = http::verb::get, const std::string& body = "",
                              const std::vector<std::pair<std::string, std::string>>& headers = {}) {
  net::io_context ioc;
  tcp::socket socket(ioc);
  socket.connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), uint16_t(port)));
  http::request<http::string_body> req{method, target, 11};
  req.set(http::field::host, "127.0.0.1");
  if (!cookie.empty()) req.set(http::field::cookie, cookie);
  for (const auto& [name, value] : headers) req.set(name, value);
  if (!body.empty()) req.body() = body;
  req.prepare_payload();
  http::write(socket, req);
  beast::flat_buffer buf;
  http::response_parser<http::string_body> parser;
  parser.body_limit(64 << 20);
  beast::error_code ec;
  http::read(socket, buf, parser, ec);
  HttpReply r;
  if (ec && ec != http::error::end_of_stream) return r;
  r.res = parser.release();
  r.status = int(r.res.result_int());
  r.body = r.res.body();
  return r;
}

struct WsMessage {
  bool binary = false;
  std::string data;
};

// The status of a WebSocket upgrade request (101 when accepted), sent by hand: Beast's client does not
// hand back a declined upgrade's response.
inline int upgrade_status(int port, const std::string& target, const std::string& cookie = "") {
  return http_request(port, target, cookie, http::verb::get, "",
                      {{"Connection", "Upgrade"}, {"Upgrade", "websocket"}, {"Sec-WebSocket-Version", "13"},
                       {"Sec-WebSocket-Key", "dGhlIHNhbXBsZSBub25jZQ=="}})
      .status;
}

class WsClient {
public:
  // Connects and upgrades at `target`; `receive_buffer` > 0 shrinks the socket's receive buffer (a
  // client that does not read then stalls the server's writes quickly).
  explicit WsClient(int port, const std::string& target, const std::string& cookie = "", int receive_buffer = 0)
      : ws_(ioc_) {
    auto& sock = beast::get_lowest_layer(ws_).socket();
    sock.open(tcp::v4());
    if (receive_buffer > 0) sock.set_option(net::socket_base::receive_buffer_size(receive_buffer));
    sock.connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), uint16_t(port)));
    ws_.set_option(websocket::stream_base::decorator([cookie](websocket::request_type& req) {
      if (!cookie.empty()) req.set(http::field::cookie, cookie);
    }));
    ws_.read_message_max(64 << 20);
    ws_.handshake(response_, "127.0.0.1", target, handshake_error_);
    if (!handshake_error_) start_read();
  }
  bool connected() const { return !handshake_error_; }
  bool closed() const { return closed_; }

  void send(const std::string& text) {
    bool done = false;
    ws_.text(true);
    ws_.async_write(net::buffer(text), [&](beast::error_code ec, size_t) {
      done = true;
      if (ec) closed_ = true;
    });
    run_until([&] { return done; }, 10);
  }
  // The next message within `seconds`; nullopt on timeout or when the connection closed.
  std::optional<WsMessage> read(double seconds = 10) {
    run_until([&] { return !inbox_.empty() || closed_; }, seconds);
    if (inbox_.empty()) return std::nullopt;
    WsMessage m = std::move(inbox_.front());
    inbox_.pop_front();
    return m;
  }
  // The first message for which pred holds (others are skipped), within `seconds`.
  std::optional<WsMessage> read_until(const std::function<bool(const WsMessage&)>& pred, double seconds = 10) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    while (true) {
      const double left = std::chrono::duration<double>(end - std::chrono::steady_clock::now()).count();
      if (left <= 0) return std::nullopt;
      std::optional<WsMessage> m = read(left);
      if (!m) return std::nullopt;
      if (pred(*m)) return m;
    }
  }
  // Runs the client for `seconds`, collecting messages.
  void pump(double seconds) { run_until([] { return false; }, seconds); }
  std::deque<WsMessage>& inbox() { return inbox_; }

private:
  void start_read() {
    ws_.async_read(buf_, [this](beast::error_code ec, size_t) {
      if (ec) {
        closed_ = true;
        return;
      }
      inbox_.push_back({ws_.got_binary(), beast::buffers_to_string(buf_.data())});
      buf_.consume(buf_.size());
      start_read();
    });
  }
  void run_until(const std::function<bool()>& done, double seconds) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    while (!done() && std::chrono::steady_clock::now() < end) {
      ioc_.restart();
      ioc_.run_one_for(std::chrono::milliseconds(20));
    }
  }

  net::io_context ioc_;
  websocket::stream<beast::tcp_stream> ws_;
  websocket::response_type response_;
  beast::error_code handshake_error_;
  beast::flat_buffer buf_;
  std::deque<WsMessage> inbox_;
  bool closed_ = false;
};

}  // namespace vnr::test
