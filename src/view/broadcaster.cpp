// The broadcaster thread: waits on the engine's frames, encodes each image once and hands the frame
// to every session; sends the state when its version changed (<= 20 Hz) and each client the losses it
// has not had yet (<= 10 Hz). It never waits on a socket: sessions take what it posts.
#include <algorithm>
#include <chrono>
#include "view/jpeg.h"
#include "view/protocol.h"
#include "view/server_core.h"

namespace vnr::view {

namespace {

using Clock = std::chrono::steady_clock;

uint64_t ns_since(Clock::time_point t0) {
  return uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - t0).count());
}

std::shared_ptr<const EncodedFrame> encode_frame(const ViewerFrame& f, JpegEncoder& jpeg, ServerCore& core) {
  auto out = std::make_shared<EncodedFrame>();
  for (const ViewerImage& im : f.images) {
    if (im.width <= 0 || im.height <= 0 || im.rgba.size() != size_t(im.width) * size_t(im.height) * 4) continue;
    std::string msg = frame_message_head(f, im);
    const auto t0 = Clock::now();
    jpeg.encode(im.rgba.data(), im.width, im.height, &msg);
    core.encode_ns += ns_since(t0);
    core.images_encoded++;
    out->messages.push_back(std::move(msg));
  }
  core.frames_encoded++;
  return out;
}

// All losses so far (the engine's list is append-only until a training reset starts it over).
struct LossCache {
  std::vector<float> values;
  int64_t last_step = 0;

  // false when the engine's losses started over (the caller resends from 0).
  bool update(const ViewerEngine& engine, const ViewerTraining& t) {
    bool kept = true;
    if (t.n_losses < values.size() || t.step < last_step) {
      values.clear();
      kept = false;
    }
    last_step = t.step;
    if (t.n_losses > values.size()) {
      std::vector<float> more = engine.losses(values.size());
      values.insert(values.end(), more.begin(), more.end());
    }
    return kept;
  }
};

void send_losses(ServerCore& core, const LossCache& cache, bool kept,
                 const std::vector<std::shared_ptr<WsSession>>& sessions) {
  std::vector<std::array<double, 2>> psnr;
  bool have_psnr = false;
  for (const auto& s : sessions) {
    if (!kept) s->losses_sent = 0;
    if (s->losses_busy || s->losses_sent >= cache.values.size()) continue;
    if (!have_psnr) psnr = core.engine->psnr_history(), have_psnr = true;
    const size_t n = std::min(kMaxLossesPerMessage, cache.values.size() - s->losses_sent);
    s->losses_busy = true;
    s->send_losses(losses_message(s->losses_sent, cache.values.data() + s->losses_sent, n, psnr));
    s->losses_sent += n;
  }
}

}  // namespace

void run_broadcaster(ServerCore& core, const std::atomic<bool>& stop) {
  JpegEncoder jpeg;
  ViewerEngine& engine = *core.engine;
  uint64_t last_id = 0, last_version = 0;
  std::shared_ptr<const ViewerFrame> newest;  // kept while nobody watches: a new client gets it
  uint64_t encoded_id = 0;
  LossCache losses;
  auto next_state = Clock::now(), next_losses = Clock::now();
  while (!stop) {
    if (auto f = engine.wait_frame(last_id, 0.02)) {
      last_id = f->id;
      newest = std::move(f);
    }
    auto sessions = core.live_sessions();
    const auto now = Clock::now();
    const bool frame_due = newest && newest->id != encoded_id && !sessions.empty();
    // The state a frame was rendered with goes out before the frame (a client sees its change in the
    // state, then the frame showing it), and otherwise at most every 50 ms.
    if (now >= next_state || (frame_due && newest->state_version > last_version)) {
      next_state = now + std::chrono::milliseconds(50);
      const ViewerState st = engine.state();
      if (st.version != last_version) {
        last_version = st.version;
        auto msg = std::make_shared<const std::string>(state_message(st));
        for (const auto& s : sessions) s->send_state(msg);
      }
      if (now >= next_losses) {
        next_losses = now + std::chrono::milliseconds(100);
        const bool kept = losses.update(engine, st.training);
        send_losses(core, losses, kept, sessions);
      }
    }
    if (frame_due) {
      const auto t0 = Clock::now();
      std::shared_ptr<const EncodedFrame> enc = encode_frame(*newest, jpeg, core);
      encoded_id = newest->id;
      {
        std::lock_guard lk(core.sessions_mu);
        core.latest_frame = enc;
      }
      for (const auto& s : sessions) s->send_frame(enc);
      core.broadcast_ns += ns_since(t0);
    }
  }
}

}  // namespace vnr::view
