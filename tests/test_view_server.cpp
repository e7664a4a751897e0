// The `vnr view` server (src/view/) over a real vnr::ViewerEngine on a small generated volume, talked
// to through Beast clients on 127.0.0.1: access rules, static files, the WebSocket protocol, frames
// against the engine's own frames, slow clients, and the `vnr view` command line.
#include <gtest/gtest.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>
#include <cmath>
#include <map>
#include <regex>
#include <thread>
#include "test_support.h"
#include "view/access.h"
#include "view/jpeg.h"
#include "view/protocol.h"
#include "view/server.h"
#include "view/web_assets.h"
#include "view_client.h"
#include "vnr/render/image.h"
#include "vnr/viewer.h"

using namespace vnr;
using namespace vnr::test;
using vnr::view::ViewServer;

namespace {

Json json_of(const WsMessage& m) { return m.binary ? Json() : Json::parse(m.data); }
bool is_type(const WsMessage& m, const char* type) { return !m.binary && json_of(m).value("type", "") == type; }

// PSNR (peak 255) over RGB of two RGBA8 images of one size.
double psnr_rgba8(const std::vector<uint8_t>& a, const std::vector<uint8_t>& b) {
  double se = 0;
  size_t n = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    if (i % 4 == 3) continue;
    const double d = double(a[i]) - double(b[i]);
    se += d * d;
    ++n;
  }
  return se == 0 ? 999 : 10 * std::log10(255.0 * 255.0 / (se / double(n)));
}

// One engine and one server for the whole suite: a 24^3 volume, a 64 x 64 viewport, models saved in
// the suite's directory.
class ViewServerTest : public ::testing::Test {
protected:
  static void SetUpTestSuite() {
    dir_ = new std::string(temp_dir("vnr_view_server"));
    std::filesystem::create_directories(*dir_ + "/models");
    synth_volume("marschner-lobb", Int3{24, 24, 24}, *dir_ + "/ml.json");
    ViewerSetup setup;
    setup.input = *dir_ + "/ml.json";
    setup.save_dir = *dir_ + "/models";
    setup.config = "small";
    engine_ = new ViewerEngine(setup);
    engine_->set_viewport(64, 64);
    view::ServerOptions options;
    options.port = 0;
    options.send_buffer_bytes = 16 * 1024;  // a client that does not read stalls after a few frames
    server_ = new ViewServer(options);
    server_->start(*engine_);
  }
  static void TearDownTestSuite() {
    delete server_;
    delete engine_;
    delete dir_;
  }
  static int port() { return server_->port(); }
  static std::string token_query() { return "?token=" + server_->token(); }
  static std::string cookie() { return "vnr_token=" + server_->token(); }
  // A connected client past its hello message.
  static std::unique_ptr<WsClient> client(int receive_buffer = 0) {
    auto c = std::make_unique<WsClient>(port(), "/ws" + token_query(), "", receive_buffer);
    EXPECT_TRUE(c->connected());
    if (receive_buffer == 0) EXPECT_TRUE(c->read_until([](const WsMessage& m) { return is_type(m, "hello"); }));
    return c;
  }
  // Waits until the engine publishes no new frame for `quiet` seconds (accumulation complete); the
  // newest frame then.
  static std::shared_ptr<const ViewerFrame> settle(double quiet = 1.0) {
    std::shared_ptr<const ViewerFrame> f = engine_->wait_frame(0, 10);
    while (auto next = engine_->wait_frame(f->id, quiet)) f = next;
    return f;
  }

  static std::string* dir_;
  static ViewerEngine* engine_;
  static ViewServer* server_;
};
std::string* ViewServerTest::dir_ = nullptr;
ViewerEngine* ViewServerTest::engine_ = nullptr;
ViewServer* ViewServerTest::server_ = nullptr;

}  // namespace

// ---- access --------------------------------------------------------------------------------------------

TEST(ViewAccess, TokensQueriesAndCookies) {
  const std::string t = view::make_token(), u = view::make_token();
  EXPECT_EQ(t.size(), 32u);
  EXPECT_EQ(t.find_first_not_of("0123456789abcdef"), std::string::npos);
  EXPECT_NE(t, u);
  EXPECT_TRUE(view::constant_time_equal(t, t));
  EXPECT_FALSE(view::constant_time_equal(t, u));
  EXPECT_FALSE(view::constant_time_equal(t, t.substr(0, 31)));
  EXPECT_EQ(view::query_value("a=1&token=xy&b=2", "token"), "xy");
  EXPECT_EQ(view::query_value("mytoken=xy", "token"), "");
  EXPECT_EQ(view::cookie_value("a=1; vnr_token=abc ;b=2", "vnr_token"), "abc");
  EXPECT_TRUE(view::check_access(t, "/x?token=" + t, "").granted);
  EXPECT_EQ(view::check_access(t, "/x?token=" + t, "").source, view::TokenSource::Query);
  EXPECT_EQ(view::check_access(t, "/x", "vnr_token=" + t).source, view::TokenSource::Cookie);
  EXPECT_FALSE(view::check_access(t, "/x?token=" + u, "vnr_token=" + u).granted);
  EXPECT_FALSE(view::check_access(t, "/x?token=", "").granted);
  EXPECT_FALSE(view::check_access("", "/x?token=", "").granted);
}

TEST_F(ViewServerTest, HttpNeedsTheTokenAndServesOnlyTheEmbeddedFiles) {
  EXPECT_EQ(http_request(port(), "/").status, 403);
  EXPECT_EQ(http_request(port(), "/?token=0123456789abcdef0123456789abcdef").status, 403);
  EXPECT_EQ(http_request(port(), "/viewer.js", "vnr_token=wrong").status, 403);
  HttpReply page = http_request(port(), "/" + token_query());
  ASSERT_EQ(page.status, 200);
  EXPECT_EQ(page.res[http::field::content_type], "text/html; charset=utf-8");
  EXPECT_EQ(page.body, std::string(view::find_web_asset("/index.html")->bytes()));
  // The URL token becomes an HttpOnly, SameSite=Strict cookie, and the cookie alone lets the page in.
  const std::string set_cookie(page.res[http::field::set_cookie]);
  EXPECT_HAS(set_cookie, cookie());
  EXPECT_HAS(set_cookie, "HttpOnly");
  EXPECT_HAS(set_cookie, "SameSite=Strict");
  for (const char* path : {"/index.html", "/viewer.js", "/viewer.css"}) {
    HttpReply r = http_request(port(), path, cookie());
    EXPECT_EQ(r.status, 200) << path;
    EXPECT_EQ(r.body, std::string(view::find_web_asset(path)->bytes())) << path;
  }
  for (const char* path : {"/../../etc/passwd", "/CMakeLists.txt", "/src/view/web/index.html", "/web/viewer.js",
                           "/%2e%2e/%2e%2e/etc/passwd", "/ws/../index.html"})
    EXPECT_EQ(http_request(port(), path, cookie()).status, 404) << path;
  EXPECT_EQ(http_request(port(), "/index.html", cookie(), http::verb::post, "x=1").status, 413);
  EXPECT_EQ(http_request(port(), "/index.html", cookie(), http::verb::delete_).status, 405);
  EXPECT_EQ(http_request(port(), "/", cookie(), http::verb::get, "", {{"X-Padding", std::string(9000, 'a')}}).status, 431);
  // The downloads are the engine's.
  HttpReply scene = http_request(port(), "/scene.json", cookie());
  EXPECT_EQ(scene.status, 200);
  EXPECT_EQ(scene.body, engine_->scene_json());
  EXPECT_HAS(std::string(scene.res[http::field::content_disposition]), "attachment");
  EXPECT_EQ(http_request(port(), "/tf.json", cookie()).body, engine_->tf_json());
}

TEST_F(ViewServerTest, WebSocketUpgradeNeedsTheToken) {
  EXPECT_EQ(upgrade_status(port(), "/ws"), 403);
  EXPECT_EQ(upgrade_status(port(), "/ws?token=abc", "vnr_token=def"), 403);
  EXPECT_EQ(upgrade_status(port(), "/index.html" + token_query()), 404);
  EXPECT_EQ(upgrade_status(port(), "/ws" + token_query()), 101);
  EXPECT_FALSE(WsClient(port(), "/ws").connected());
  WsClient by_cookie(port(), "/ws", cookie());
  ASSERT_TRUE(by_cookie.connected());
  EXPECT_TRUE(by_cookie.read_until([](const WsMessage& m) { return is_type(m, "hello"); }));
}

// ---- protocol ----------------------------------------------------------------------------------------

TEST_F(ViewServerTest, HelloCarriesInfoStateAndHistogram) {
  WsClient c(port(), "/ws" + token_query());
  ASSERT_TRUE(c.connected());
  std::optional<WsMessage> m = c.read();
  ASSERT_TRUE(m && !m->binary);
  const Json hello = Json::parse(m->data);
  EXPECT_EQ(hello["type"], "hello");  // the first message
  EXPECT_EQ(hello["info"]["dims"], Json({24, 24, 24}));
  EXPECT_EQ(hello["info"]["description"], engine_->info().description);
  EXPECT_EQ(hello["info"]["can_train"], engine_->info().can_train);
  EXPECT_EQ(hello["info"]["colormaps"].get<std::vector<std::string>>(), engine_->info().colormaps);
  EXPECT_EQ(hello["histogram"].get<std::vector<uint32_t>>(), engine_->histogram(256));
  const Json& st = hello["state"];
  EXPECT_LE(st["version"].get<uint64_t>(), engine_->state().version);
  EXPECT_EQ(st["viewport"], Json({{"width", 64}, {"height", 64}}));
  for (const char* k : {"camera", "view", "tf", "render", "training", "error_count", "last_error"})
    EXPECT_TRUE(st.contains(k)) << k;
}

TEST_F(ViewServerTest, CameraChangeShowsInStateAndInALaterFrame) {
  auto c = client();
  const Camera before = engine_->state().camera;
  const Vec3f eye{before.eye.x + 3.0f, before.eye.y + 2.0f, before.eye.z};
  c->send(Json{{"type", "camera"}, {"eye", {eye.x, eye.y, eye.z}}, {"interacting", false}}.dump());
  std::optional<WsMessage> st = c->read_until([&](const WsMessage& m) {
    return is_type(m, "state") && json_of(m)["state"]["camera"]["eye"] == Json({eye.x, eye.y, eye.z});
  });
  ASSERT_TRUE(st) << "no state with the new camera";
  // The server sends the state a frame was rendered with before the frame: frames skipped above are
  // older than this state.
  const uint64_t version = json_of(*st)["state"]["version"];
  EXPECT_EQ(engine_->state().camera.eye.x, eye.x);
  EXPECT_EQ(engine_->state().camera.center.x, before.center.x);  // a partial update
  std::optional<WsMessage> frame = c->read_until([&](const WsMessage& m) {
    return m.binary && view::split_frame_message(m.data).header["version"].get<uint64_t>() >= version;
  });
  ASSERT_TRUE(frame) << "no frame rendered with the new camera";
  const view::FrameMessageParts parts = view::split_frame_message(frame->data);
  for (const char* k : {"frame", "view", "version", "width", "height", "refined", "accumulated", "render_ms",
                        "train_ms", "step"})
    EXPECT_TRUE(parts.header.contains(k)) << k;
  const view::DecodedJpeg img = view::decode_jpeg(parts.jpeg);
  EXPECT_EQ(img.width, parts.header["width"].get<int>());
  EXPECT_EQ(img.height, parts.header["height"].get<int>());
}

TEST_F(ViewServerTest, BadMessagesGetAnErrorAndTheConnectionStays) {
  auto c = client();
  const uint64_t version = engine_->state().version;
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"{not json", "malformed JSON"},
      {"[1, 2]", "JSON object"},
      {R"({"camera": 1})", "type"},
      {R"({"type": "fly"})", "unknown message type"},
      {R"({"type": "view", "split": "half"})", "view.split"},
      {R"({"type": "view", "layout": "grid"})", "view.layout"},
      {R"({"type": "viewport", "width": 8})", "viewport.width"},
      {R"({"type": "viewport", "width": 100.5})", "viewport.width"},
      {R"({"type": "camera", "eye": [1, 2]})", "camera.eye"},
      {R"({"type": "cursor", "x": 0.5})", "cursor.x and cursor.y go together"},
      {R"({"type": "cursor", "x": 1.5, "y": 0.5})", "cursor.x"},
      {R"({"type": "render", "step": -1})", "render.step"},
      {R"({"type": "render", "mode": "xray"})", "render mode 'xray'"},  // the library's check and list
      {R"({"type": "render", "strategy": "fast"})", "allowed: auto, cache, streaming, inshader"},
      {R"({"type": "render", "macrocells": 3})", "render.macrocells must be a string"},
      {R"({"type": "train", "action": "fly"})", "train.action"},
      {R"({"type": "tf", "opacity": [[0, 0.5], [1]]})", "tf.opacity"},
      {R"({"type": "tf", "colormap": "no-such-colormap"})", "tf"},  // refused by the engine
      {R"({"type": "tf_load", "text": "{]"})", "tf_load"},
      {R"({"type": "save"})", "name"},
  };
  for (const auto& [text, needle] : cases) {
    c->send(text);
    std::optional<WsMessage> m = c->read_until([](const WsMessage& m) { return is_type(m, "error"); });
    ASSERT_TRUE(m) << text;
    EXPECT_HAS(json_of(*m)["message"].get<std::string>(), needle);
  }
  c->send(R"({"type": "cursor", "x": 0.25, "y": 0.75})");  // accepted: no reply, no new state
  c->send(R"({"type": "cursor"})");
  c->send(R"({"type": "ping", "id": 7, "unknown_field": true})");
  std::optional<WsMessage> pong = c->read_until([](const WsMessage& m) { return is_type(m, "pong"); });
  ASSERT_TRUE(pong);
  EXPECT_EQ(json_of(*pong)["id"], 7);
  EXPECT_EQ(engine_->state().version, version);  // nothing changed
}

TEST_F(ViewServerTest, OversizedMessageClosesThatConnectionOnly) {
  auto big = client();
  auto other = client();
  big->send(R"({"type": "ping", "id": ")" + std::string(1100 * 1024, 'x') + "\"}");
  EXPECT_FALSE(big->read_until([](const WsMessage& m) { return is_type(m, "pong"); }, 5));
  EXPECT_TRUE(big->closed());
  other->send(R"({"type": "ping", "id": 1})");
  EXPECT_TRUE(other->read_until([](const WsMessage& m) { return is_type(m, "pong"); }));
  auto fresh = client();  // still accepting
  fresh->send(R"({"type": "ping", "id": 2})");
  EXPECT_TRUE(fresh->read_until([](const WsMessage& m) { return is_type(m, "pong"); }));
}

TEST_F(ViewServerTest, TwoClientsSeeFramesAndEachOthersChanges) {
  auto a = client(), b = client();
  a->send(R"({"type": "render", "step": 0.75})");
  ASSERT_TRUE(b->read_until([](const WsMessage& m) {
    return is_type(m, "state") && json_of(m)["state"]["render"]["step"] == 0.75;
  }));
  b->send(R"({"type": "view", "split": 0.25})");
  ASSERT_TRUE(a->read_until([](const WsMessage& m) {
    return is_type(m, "state") && json_of(m)["state"]["view"]["split"] == 0.25;
  }));
  // A change that needs a new image: both get the frame.
  Camera cam = engine_->state().camera;
  a->send(Json{{"type", "camera"}, {"eye", {cam.eye.x + 1, cam.eye.y, cam.eye.z}}}.dump());
  uint64_t version = 0;
  ASSERT_TRUE(b->read_until([&](const WsMessage& m) {
    if (!is_type(m, "state") || json_of(m)["state"]["camera"]["eye"][0] != cam.eye.x + 1) return false;
    version = json_of(m)["state"]["version"];
    return true;
  }));
  for (WsClient* c : {a.get(), b.get()})
    EXPECT_TRUE(c->read_until([&](const WsMessage& m) {
      return m.binary && view::split_frame_message(m.data).header["version"].get<uint64_t>() >= version;
    }));
}

TEST_F(ViewServerTest, AClientThatNeverReadsDoesNotStallTheOthers) {
  // The stalled client's tiny receive buffer fills with its hello; after that every frame for it is
  // replaced by the next one while the write of the hello hangs.
  auto stalled = client(/*receive_buffer*/ 1024);
  auto reader = client();
  // The window below counts frames, not the engine's start (a probe, a first training chunk), which a
  // sanitizer build on a loaded machine can stretch past it.
  ASSERT_TRUE(engine_->wait_frame(0, 60)) << "the engine published no frame";
  const view::ServerStats before = server_->stats();
  const Camera cam = engine_->state().camera;
  int frames = 0;
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(3);
  for (int i = 0; std::chrono::steady_clock::now() < end; ++i) {
    const float a = 0.05f * float(i);
    const Vec3f d = cam.eye - cam.center;
    const Vec3f eye{cam.center.x + d.x * std::cos(a) + d.z * std::sin(a), cam.eye.y,
                    cam.center.z - d.x * std::sin(a) + d.z * std::cos(a)};
    reader->send(Json{{"type", "camera"}, {"eye", {eye.x, eye.y, eye.z}}, {"interacting", true}}.dump());
    reader->pump(0.03);
    for (auto& m : reader->inbox()) frames += m.binary;
    reader->inbox().clear();
  }
  reader->send(R"({"type": "camera", "interacting": false})");
  EXPECT_GE(frames, 10) << "the reading client got too few frames";
  const view::ServerStats after = server_->stats();
  EXPECT_GT(after.frames_dropped, before.frames_dropped);
  EXPECT_FALSE(stalled->closed());
}

TEST_F(ViewServerTest, BinaryFrameIsTheEnginesFrameWithinJpegTolerance) {
  const std::shared_ptr<const ViewerFrame> f = settle();
  auto c = client();  // a new client gets the newest frame at once
  std::map<std::string, view::DecodedJpeg> got;
  while (got.size() < f->images.size()) {
    std::optional<WsMessage> m = c->read_until([](const WsMessage& m) { return m.binary; }, 10);
    ASSERT_TRUE(m);
    const view::FrameMessageParts p = view::split_frame_message(m->data);
    if (p.header["frame"].get<uint64_t>() != f->id) continue;
    EXPECT_EQ(p.header["version"].get<uint64_t>(), f->state_version);
    EXPECT_EQ(p.header["refined"].get<bool>(), f->refined);
    EXPECT_EQ(p.header["accumulated"].get<int>(), f->accumulated);
    got[p.header["view"].get<std::string>()] = view::decode_jpeg(p.jpeg);
  }
  for (const ViewerImage& im : f->images) {
    ASSERT_TRUE(got.count(im.view)) << im.view;
    const view::DecodedJpeg& d = got[im.view];
    ASSERT_EQ(d.width, im.width);
    ASSERT_EQ(d.height, im.height);
    EXPECT_GT(psnr_rgba8(d.rgba, im.rgba), 30.0) << im.view;
  }
}

TEST_F(ViewServerTest, ScreenshotIsTheEnginesScreenshotAsPng) {
  settle();
  HttpReply r = http_request(port(), "/screenshot.png", cookie());
  ASSERT_EQ(r.status, 200) << r.body;
  EXPECT_EQ(r.res[http::field::content_type], "image/png");
  EXPECT_HAS(std::string(r.res[http::field::content_disposition]), "vnr-screenshot.png");
  const std::string png_path = *dir_ + "/shot.png", ref_path = *dir_ + "/ref.png";
  write_file_atomic(png_path, r.body);
  write_image(ref_path, engine_->screenshot(10));
  const Image got = read_image(png_path), ref = read_image(ref_path);
  ASSERT_EQ(got.width, ref.width);
  ASSERT_EQ(got.height, ref.height);
  EXPECT_EQ(compare_images(got, ref).mse, 0.0);
}

TEST(ViewPng, EncodePngIsWhatWriteImageWrites) {
  Image img(13, 7);
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) img.at(x, y) = Vec4f{x / 12.0f, y / 6.0f, 1.2f - x * 0.1f, 0.5f};
  const std::string d = temp_dir("vnr_view_png");
  write_image(d + "/a.png", img);
  const std::vector<uint8_t> bytes = encode_png(img);
  EXPECT_EQ(std::string(bytes.begin(), bytes.end()), read_file(d + "/a.png"));
  write_file_atomic(d + "/b.png", std::string(bytes.begin(), bytes.end()));
  EXPECT_EQ(compare_images(read_image(d + "/b.png"), read_image(d + "/a.png")).mse, 0.0);
  EXPECT_THROW(encode_png(Image()), Error);
}

TEST_F(ViewServerTest, SaveFollowsTheNameRules) {
  auto c = client();
  for (const char* bad : {"../evil", "/tmp/x", "a/b", ".hidden", ""}) {
    c->send(Json{{"type", "save"}, {"name", bad}}.dump());
    std::optional<WsMessage> m = c->read_until([](const WsMessage& m) { return is_type(m, "error"); });
    ASSERT_TRUE(m) << bad;
  }
  c->send(R"({"type": "save", "name": "snapshot"})");
  std::optional<WsMessage> m =
      c->read_until([](const WsMessage& m) { return is_type(m, "saved") || is_type(m, "error"); }, 30);
  ASSERT_TRUE(m);
  ASSERT_TRUE(is_type(*m, "saved")) << m->data;
  const std::string path = json_of(*m)["path"];
  EXPECT_TRUE(file_exists(path));
  EXPECT_EQ(std::filesystem::path(path).parent_path(), std::filesystem::path(*dir_ + "/models"));
}

TEST_F(ViewServerTest, LossesArriveIncrementally) {
  auto c = client();
  c->send(R"({"type": "train", "action": "start", "budget": 0.02})");
  size_t next = 0;
  std::vector<float> values;
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (values.size() < 20 && std::chrono::steady_clock::now() < end) {
    std::optional<WsMessage> m = c->read_until([](const WsMessage& m) { return is_type(m, "losses"); }, 10);
    ASSERT_TRUE(m);
    const Json j = json_of(*m);
    ASSERT_EQ(j["from"].get<size_t>(), next);  // each message continues where the last ended
    for (const Json& v : j["values"]) values.push_back(v.get<float>());
    next = values.size();
    EXPECT_LE(j["values"].size(), view::kMaxLossesPerMessage);
    EXPECT_TRUE(j["psnr"].is_array());
  }
  c->send(R"({"type": "train", "action": "pause"})");
  ASSERT_GE(values.size(), 20u);
  const std::vector<float> engine_losses = engine_->losses(0);
  ASSERT_GE(engine_losses.size(), values.size());
  for (size_t i = 0; i < values.size(); ++i) EXPECT_EQ(values[i], engine_losses[i]) << i;
  ASSERT_TRUE(c->read_until([](const WsMessage& m) {
    return is_type(m, "state") && json_of(m)["state"]["training"]["state"] == "paused";
  }));
}

// ---- the command line ---------------------------------------------------------------------------------

namespace {

// `vnr view ARGS` as a child process: its stdout through a pipe, stderr into a file.
struct ViewProcess {
  pid_t pid = -1;
  int out_fd = -1;
  std::string err_path;

  ViewProcess(const std::vector<std::string>& args, const std::string& dir) : err_path(dir + "/view_stderr.txt") {
    int fds[2];
    EXPECT_EQ(pipe(fds), 0);
    pid = fork();
    if (pid == 0) {
      dup2(fds[1], 1);
      const int err = open(err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      dup2(err, 2);
      close(fds[0]);
      std::vector<char*> argv{const_cast<char*>(VNR_CLI_PATH), const_cast<char*>("view")};
      for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
      argv.push_back(nullptr);
      execv(VNR_CLI_PATH, argv.data());
      _exit(127);
    }
    close(fds[1]);
    out_fd = fds[0];
  }
  ~ViewProcess() {
    if (pid > 0 && exit_code(0) == -2) {
      kill(pid, SIGKILL);
      waitpid(pid, nullptr, 0);
    }
    if (out_fd >= 0) close(out_fd);
  }
  // The first stdout line, waiting up to `seconds`.
  std::string first_line(double seconds) {
    std::string line;
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    while (std::chrono::steady_clock::now() < end) {
      pollfd p{out_fd, POLLIN, 0};
      if (poll(&p, 1, 50) <= 0) continue;
      char c;
      if (read(out_fd, &c, 1) != 1) break;
      if (c == '\n') return line;
      line += c;
    }
    return line;
  }
  // The exit status within `seconds`; -2 while it still runs, -1 when killed by a signal.
  int exit_code(double seconds) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    do {
      int st = 0;
      const pid_t r = waitpid(pid, &st, WNOHANG);
      if (r == pid) {
        pid = -1;
        return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    } while (std::chrono::steady_clock::now() < end);
    return -2;
  }
};

}  // namespace

TEST(ViewCli, PrintsTheUrlServesAndStopsOnSigterm) {
  const std::string d = temp_dir("vnr_view_cli");
  synth_volume("marschner-lobb", Int3{16, 16, 16}, d + "/ml.json");
  ViewProcess p({d + "/ml.json", "--port", "0", "--config", "small"}, d);
  const std::string line = p.first_line(60);
  std::smatch m;
  ASSERT_TRUE(std::regex_match(line, m, std::regex(R"(vnr view: http://127\.0\.0\.1:(\d+)/\?token=([0-9a-f]{32}))")))
      << line << "\n" << read_file(p.err_path);
  const int port = std::stoi(m[1].str());
  const std::string token = m[2].str();
  EXPECT_EQ(http_request(port, "/").status, 403);
  EXPECT_EQ(http_request(port, "/?token=" + token).status, 200);
  WsClient c(port, "/ws?token=" + token);
  ASSERT_TRUE(c.connected());
  EXPECT_TRUE(c.read_until([](const WsMessage& m) { return is_type(m, "hello"); }));
  ASSERT_EQ(kill(p.pid, SIGTERM), 0);
  EXPECT_EQ(p.exit_code(10), 0);
  EXPECT_HAS(read_file(p.err_path), "vnr view: stopped");
}

TEST(ViewCli, BusyPortAndBadInputAreOneErrorLine) {
  const std::string d = temp_dir("vnr_view_cli");
  synth_volume("marschner-lobb", Int3{16, 16, 16}, d + "/ml.json");
  net::io_context ioc;
  tcp::acceptor busy(ioc, tcp::endpoint(net::ip::make_address("127.0.0.1"), 0));
  const int port = busy.local_endpoint().port();
  expect_error("view " + d + "/ml.json --port " + std::to_string(port), "cannot listen on 127.0.0.1:" + std::to_string(port));
  expect_error("view " + d + "/missing.json --port 0", "missing.json");
  expect_error("view " + d + "/ml.json --port 0 --host not-an-address", "not-an-address");
  expect_error("view " + d + "/ml.json --port 70000", "port");
}
