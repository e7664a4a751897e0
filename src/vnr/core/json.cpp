#include "vnr/json.h"
#include <algorithm>
#include <cctype>
#include "vnr/error.h"
#include "vnr/fileio.h"

namespace vnr {

Json parse_json_text(const std::string& text, const std::string& what) {
  try {
    return Json::parse(text, nullptr, /*allow_exceptions=*/true, /*ignore_comments=*/true);
  } catch (const Json::exception& e) {
    // parse_error, or out_of_range for a number beyond double (1e999). nlohmann's message carries the
    // byte position; keep it on one line.
    std::string msg = e.what();
    std::replace(msg.begin(), msg.end(), '\n', ' ');
    fail("{}: invalid JSON ({})", what, msg);
  }
}

Json parse_json_file(const std::string& path) { return parse_json_text(read_file(path), path); }

std::string to_lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return s;
}

bool iequals(const std::string& a, const std::string& b) { return to_lower(a) == to_lower(b); }

std::string option_name_of(const std::string& key) {
  std::string option = "--" + key;
  std::replace(option.begin(), option.end(), '_', '-');
  return option;
}

}  // namespace vnr
