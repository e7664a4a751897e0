// One browser tab's WebSocket: reads client messages (each answered or applied at once, slow ones on
// the worker), writes replies, state and frames one at a time with frames dropped, never queued.
#include "view/protocol.h"
#include "view/server_core.h"

namespace vnr::view {

WsSession::WsSession(tcp::socket&& socket, ServerCore& core) : ws_(std::move(socket)), core_(core) {}

void WsSession::start(http::request<http::empty_body> req) {
  ws_.set_option(websocket::stream_base::timeout::suggested(beast::role_type::server));
  ws_.read_message_max(kMessageLimit);
  ws_.auto_fragment(false);
  beast::error_code ec;
  if (core_.send_buffer_bytes > 0)
    beast::get_lowest_layer(ws_).socket().set_option(net::socket_base::send_buffer_size(core_.send_buffer_bytes), ec);
  ws_.async_accept(req, [self = shared_from_this()](beast::error_code ec) {
    if (ec) return;
    self->open_ = true;
    self->core_.add_session(self);
    self->texts_.push_back({hello_message(self->core_.engine->info(), self->core_.histogram,
                                          self->core_.engine->state()),
                            false});
    {
      std::lock_guard lk(self->core_.sessions_mu);
      self->next_frame_ = self->core_.latest_frame;
    }
    self->pump();
    self->read();
  });
}

void WsSession::read() {
  ws_.async_read(in_, [self = shared_from_this()](beast::error_code ec, size_t) { self->on_message(ec); });
}

void WsSession::on_message(beast::error_code ec) {
  // Closed by the client, too large (Beast answers with close code 1009), or a broken connection.
  if (ec) return fail_and_close();
  const bool text = ws_.got_text();
  const std::string msg = beast::buffers_to_string(in_.data());
  in_.consume(in_.size());
  if (!text) {
    texts_.push_back({error_message("binary messages are not accepted; send JSON text"), false});
  } else {
    ClientCommand command;
    std::string reply;
    try {
      command = parse_client_message(msg);
    } catch (const std::exception& e) {
      reply = error_message(e.what());
    }
    if (reply.empty() && command.slow) {
      auto self = shared_from_this();
      const bool posted = core_.worker.post([self, command] {
        std::string r = run_command(command, *self->core_.engine);
        if (!r.empty()) self->send_text(std::move(r));
      });
      if (!posted) reply = error_message(command.type + ": the server is busy; try again");
    } else if (reply.empty()) {
      reply = run_command(command, *core_.engine);
    }
    if (!reply.empty()) texts_.push_back({std::move(reply), false});
  }
  if (texts_.size() > kMaxQueuedTexts) return fail_and_close();  // it sends but never reads
  pump();
  read();
}

void WsSession::send_text(std::string message) {
  net::post(core_.ioc, [self = shared_from_this(), m = std::move(message)]() mutable {
    if (!self->open_) return;
    self->texts_.push_back({std::move(m), false});
    if (self->texts_.size() > kMaxQueuedTexts) return self->fail_and_close();
    self->pump();
  });
}

void WsSession::send_losses(std::string message) {
  net::post(core_.ioc, [self = shared_from_this(), m = std::move(message)]() mutable {
    if (!self->open_) return;
    self->texts_.push_back({std::move(m), true});
    self->pump();
  });
}

void WsSession::send_state(std::shared_ptr<const std::string> message) {
  net::post(core_.ioc, [self = shared_from_this(), m = std::move(message)]() mutable {
    if (!self->open_) return;
    self->state_ = std::move(m);
    self->pump();
  });
}

void WsSession::send_frame(std::shared_ptr<const EncodedFrame> frame) {
  net::post(core_.ioc, [self = shared_from_this(), f = std::move(frame)]() mutable {
    if (!self->open_) return;
    if (self->next_frame_) self->core_.frames_dropped++;
    self->next_frame_ = std::move(f);
    self->pump();
  });
}

void WsSession::pump() {
  if (writing_ || !open_) return;
  if (!texts_.empty()) {
    writing_text_ = std::move(texts_.front());
    texts_.pop_front();
    return write(writing_text_.bytes, false);
  }
  if (state_) {
    writing_state_ = std::move(state_);
    state_.reset();
    return write(*writing_state_, false);
  }
  if (next_frame_) {  // the newest frame wins over the rest of an older one
    if (frame_ && frame_index_ < frame_->messages.size()) core_.frames_dropped++;
    frame_ = std::move(next_frame_);
    next_frame_.reset();
    frame_index_ = 0;
  }
  if (frame_ && frame_index_ < frame_->messages.size()) {
    core_.messages_sent++;
    return write(frame_->messages[frame_index_++], true);
  }
  frame_.reset();
}

void WsSession::write(const std::string& bytes, bool binary) {
  writing_ = true;
  ws_.binary(binary);
  ws_.async_write(net::buffer(bytes), [self = shared_from_this()](beast::error_code ec, size_t) {
    self->writing_ = false;
    if (self->writing_text_.losses) self->losses_busy = false;
    self->writing_text_ = {};
    self->writing_state_.reset();
    if (ec) return self->fail_and_close();
    self->pump();
  });
}

void WsSession::fail_and_close() {
  if (!open_) return;
  open_ = false;
  core_.remove_session(this);
  losses_busy = false;
  beast::error_code ec;
  beast::get_lowest_layer(ws_).socket().shutdown(tcp::socket::shutdown_both, ec);
  beast::get_lowest_layer(ws_).socket().close(ec);
}

void WsSession::close() { fail_and_close(); }

}  // namespace vnr::view
