// Plain HTTP: the token check, the embedded page, the engine's downloads, and the upgrade to /ws.
#include <chrono>
#include <optional>
#include "view/access.h"
#include "view/server_core.h"
#include "view/web_assets.h"
#include "vnr/error.h"
#include "vnr/image.h"

namespace vnr::view {

const WebAsset* find_web_asset(std::string_view path) {
  if (path == "/") path = "/index.html";
  for (const WebAsset& a : web_assets())
    if (path == a.path) return &a;
  return nullptr;
}

namespace {

using Response = http::response<http::string_body>;

Response make_response(http::status status, std::string_view content_type, std::string body) {
  Response res{status, 11};
  res.set(http::field::server, "vnr view");
  res.set(http::field::content_type, beast::string_view(content_type.data(), content_type.size()));
  res.set(http::field::cache_control, "no-store");
  res.set("X-Content-Type-Options", "nosniff");
  // The URL carries the token: never hand it to another site.
  res.set("Referrer-Policy", "no-referrer");
  res.body() = std::move(body);
  res.prepare_payload();
  return res;
}

Response text_response(http::status status, std::string_view line) {
  return make_response(status, "text/plain; charset=utf-8", std::string(line) + "\n");
}

Response attachment(std::string_view content_type, std::string body, std::string_view filename) {
  Response res = make_response(http::status::ok, content_type, std::move(body));
  res.set(http::field::content_disposition, "attachment; filename=\"" + std::string(filename) + "\"");
  return res;
}

class HttpSession : public std::enable_shared_from_this<HttpSession> {
public:
  HttpSession(tcp::socket&& socket, ServerCore& core) : stream_(std::move(socket)), core_(core) {}

  void read() {
    parser_.emplace();
    parser_->header_limit(kRequestHeadLimit);
    parser_->body_limit(0);
    stream_.expires_after(std::chrono::seconds(30));
    http::async_read(stream_, buffer_, *parser_,
                     [self = shared_from_this()](beast::error_code ec, size_t) { self->on_read(ec); });
  }

private:
  void on_read(beast::error_code ec) {
    if (ec == http::error::end_of_stream || ec == beast::error::timeout || ec == net::error::operation_aborted)
      return close();
    if (ec == http::error::header_limit) return respond(text_response(http::status::request_header_fields_too_large,
                                                                      "request head over 8 KiB"), false);
    if (ec == http::error::body_limit || ec == http::error::unexpected_body)
      return respond(text_response(http::status::payload_too_large, "request bodies are not accepted"), false);
    if (ec) return respond(text_response(http::status::bad_request, "malformed request"), false);
    http::request<http::empty_body> req = parser_->release();
    const Access access = check_access(core_.token, to_sv(req.target()), to_sv(req[http::field::cookie]));
    const std::string_view path = split_target(to_sv(req.target())).path;
    if (!access.granted) return respond(text_response(http::status::forbidden, "forbidden: a valid token is required"), false);
    if (websocket::is_upgrade(req)) {
      if (path != "/ws") return respond(text_response(http::status::not_found, "not found"), false);
      stream_.expires_never();
      std::make_shared<WsSession>(stream_.release_socket(), core_)->start(std::move(req));
      return;
    }
    if (req.method() != http::verb::get) {
      Response res = text_response(http::status::method_not_allowed, "only GET is served");
      res.set(http::field::allow, "GET");
      return respond(std::move(res), req.keep_alive(), access);
    }
    route(std::string(path), req.keep_alive(), access);
  }

  void route(const std::string& path, bool keep_alive, Access access) {
    if (const WebAsset* a = find_web_asset(path))
      return respond(make_response(http::status::ok, a->content_type, std::string(a->bytes())), keep_alive, access);
    if (path != "/screenshot.png" && path != "/scene.json" && path != "/tf.json")
      return respond(text_response(http::status::not_found, "not found"), keep_alive, access);
    // The engine may take a while (a screenshot waits for a refined frame): on the worker.
    auto self = shared_from_this();
    const bool posted = core_.worker.post([self, path, keep_alive, access] {
      std::optional<Response> res;
      try {
        ViewerEngine& e = *self->core_.engine;
        if (path == "/screenshot.png") {
          const std::vector<uint8_t> png = encode_png(e.screenshot(10));
          res = attachment("image/png", std::string(png.begin(), png.end()), "vnr-screenshot.png");
        } else if (path == "/scene.json") {
          res = attachment("application/json", e.scene_json(), "vnr-scene.json");
        } else {
          res = attachment("application/json", e.tf_json(), "vnr-tf.json");
        }
      } catch (const std::exception& ex) {
        res = text_response(http::status::service_unavailable, ex.what());
      }
      net::post(self->core_.ioc, [self, r = std::move(*res), keep_alive, access]() mutable {
        self->respond(std::move(r), keep_alive, access);
      });
    });
    if (!posted) respond(text_response(http::status::service_unavailable, "the server is busy; try again"), false);
  }

  void respond(Response res, bool keep_alive, Access access = {}) {
    // A token that came on the URL becomes the cookie, so the page's own requests need no token.
    if (access.source == TokenSource::Query) res.set(http::field::set_cookie, token_cookie(core_.token));
    res.keep_alive(keep_alive);
    response_ = std::make_shared<Response>(std::move(res));
    stream_.expires_after(std::chrono::seconds(30));
    http::async_write(stream_, *response_, [self = shared_from_this(), keep_alive](beast::error_code ec, size_t) {
      self->response_.reset();
      if (ec || !keep_alive) return self->close();
      self->read();
    });
  }

  void close() {
    beast::error_code ec;
    stream_.socket().shutdown(tcp::socket::shutdown_send, ec);
    stream_.socket().close(ec);
  }

  beast::tcp_stream stream_;
  ServerCore& core_;
  beast::flat_buffer buffer_{kRequestHeadLimit};
  std::optional<http::request_parser<http::empty_body>> parser_;
  std::shared_ptr<Response> response_;
};

}  // namespace

void start_http_session(tcp::socket&& socket, ServerCore& core) {
  std::make_shared<HttpSession>(std::move(socket), core)->read();
}

}  // namespace vnr::view
