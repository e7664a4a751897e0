#pragma once
// The viewer's WebSocket messages (docs/VIEWER.md "WebSocket messages"): the engine's state as JSON for
// the page, and the page's messages as engine calls.
#include <array>
#include <functional>
#include <string>
#include <string_view>
#include <vector>
#include "vnr/json.h"
#include "vnr/viewer.h"

namespace vnr::view {

// The names of the messages' enums: "network", "truth", "side_by_side", "split" (the render enums go
// by render_mode_name, render_strategy_name and macrocell_mode_name).
const char* view_layout_name(ViewLayout layout);

// ---- server -> client -------------------------------------------------------------------------------

Json info_json(const ViewerInfo& info);
Json state_json(const ViewerState& state);
// The compact JSON text of a message. Strings from the engine (file names, error messages) need not be
// UTF-8: what is not is replaced rather than failing the whole message.
std::string json_text(const Json& j);
std::string hello_message(const ViewerInfo& info, const std::vector<uint32_t>& histogram, const ViewerState& state);
std::string state_message(const ViewerState& state);
// Losses values[0, n) of steps [from, from + n), and the whole PSNR history.
std::string losses_message(size_t from, const float* values, size_t n,
                           const std::vector<std::array<double, 2>>& psnr);
std::string error_message(std::string_view message);

// One binary frame message without its JPEG: uint32 little-endian header length, then the JSON header
// {"frame", "view", "version", "width", "height", "refined", "accumulated", "render_ms", "train_ms",
// "step"} of one image of the frame. The JPEG bytes follow.
std::string frame_message_head(const ViewerFrame& frame, const ViewerImage& image);
// The header JSON and the JPEG of a binary frame message (vnr::Error when it is not one).
struct FrameMessageParts {
  Json header;
  std::string_view jpeg;
};
FrameMessageParts split_frame_message(std::string_view message);

// ---- client -> server -------------------------------------------------------------------------------

// Limits of the losses messages: at most this many values in one.
constexpr size_t kMaxLossesPerMessage = 2000;

// A client message, checked: run() makes the engine calls (reading the engine's current state for the
// fields the message leaves out) and returns the reply for that client (null: none). run() throws
// vnr::Error when the engine refuses a value.
struct ClientCommand {
  std::string type;
  bool slow = false;  // may take long (writing a model): run off the network thread
  std::function<Json(ViewerEngine&)> run;
};
// vnr::Error naming what is wrong for malformed JSON, a missing or unknown type, a wrong field type or
// an invalid value. Unknown fields are ignored.
ClientCommand parse_client_message(std::string_view text);
// Runs a parsed command, never throwing: the reply text ("" = none; an "error" message on failure).
std::string run_command(const ClientCommand& command, ViewerEngine& engine);

}  // namespace vnr::view
