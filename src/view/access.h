#pragma once
// Who may use the viewer (docs/VIEWER.md "Start-up and access"): everyone who presents the token
// printed at start-up, on the URL (?token=) or in the cookie vnr_token.
#include <string>
#include <string_view>

namespace vnr::view {

// 32 lowercase hex characters from 16 bytes of /dev/urandom (vnr::Error when it cannot be read).
std::string make_token();
// Equality that takes the same time wherever the strings differ (only the length shows).
bool constant_time_equal(std::string_view a, std::string_view b);

// A request target split at '?': the path ("/ws") and the raw query ("token=...").
struct Target {
  std::string_view path, query;
};
Target split_target(std::string_view target);
// The value of `name` in a query string ("a=1&token=x") or a Cookie header ("a=1; vnr_token=x"); ""
// when absent. Values are taken verbatim (a token is plain hex: nothing to decode).
std::string_view query_value(std::string_view query, std::string_view name);
std::string_view cookie_value(std::string_view cookie_header, std::string_view name);

// What a request presented, and whether it matches.
enum class TokenSource { None, Query, Cookie };
struct Access {
  bool granted = false;
  TokenSource source = TokenSource::None;  // of the matching token
};
Access check_access(std::string_view expected_token, std::string_view target, std::string_view cookie_header);

// The Set-Cookie value that lets the page's later requests (viewer.js, /ws) in without the URL token.
std::string token_cookie(std::string_view token);

}  // namespace vnr::view
