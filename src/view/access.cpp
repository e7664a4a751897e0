// Access control of the viewer: one random token per server, compared in constant time.
#include "view/access.h"
#include <cstdio>
#include "vnr/error.h"

namespace vnr::view {

std::string make_token() {
  unsigned char bytes[16];
  FILE* f = std::fopen("/dev/urandom", "rb");
  if (!f) fail("cannot open /dev/urandom for the access token");
  const size_t got = std::fread(bytes, 1, sizeof bytes, f);
  std::fclose(f);
  if (got != sizeof bytes) fail("cannot read /dev/urandom for the access token");
  static const char hex[] = "0123456789abcdef";
  std::string token;
  for (unsigned char b : bytes) {
    token += hex[b >> 4];
    token += hex[b & 15];
  }
  return token;
}

bool constant_time_equal(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  unsigned char diff = 0;
  for (size_t i = 0; i < a.size(); ++i) diff |= static_cast<unsigned char>(a[i] ^ b[i]);
  // Keep the compiler from ending the loop early on a difference.
  volatile unsigned char result = diff;
  return result == 0;
}

Target split_target(std::string_view target) {
  const size_t q = target.find('?');
  if (q == std::string_view::npos) return {target, {}};
  return {target.substr(0, q), target.substr(q + 1)};
}

namespace {

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return s;
}

// The value of `name` in "k=v<sep>k=v...".
std::string_view pair_value(std::string_view list, std::string_view name, char sep) {
  while (!list.empty()) {
    const size_t end = list.find(sep);
    std::string_view item = trim(list.substr(0, end));
    const size_t eq = item.find('=');
    if (eq != std::string_view::npos && item.substr(0, eq) == name) return item.substr(eq + 1);
    if (end == std::string_view::npos) break;
    list.remove_prefix(end + 1);
  }
  return {};
}

}  // namespace

std::string_view query_value(std::string_view query, std::string_view name) { return pair_value(query, name, '&'); }
std::string_view cookie_value(std::string_view cookie_header, std::string_view name) {
  return pair_value(cookie_header, name, ';');
}

Access check_access(std::string_view expected, std::string_view target, std::string_view cookie_header) {
  const std::string_view from_query = query_value(split_target(target).query, "token");
  const std::string_view from_cookie = cookie_value(cookie_header, "vnr_token");
  // Both compared always, so the time does not tell which one was present.
  const bool query_ok = constant_time_equal(from_query, expected);
  const bool cookie_ok = constant_time_equal(from_cookie, expected);
  if (expected.empty()) return {};
  if (query_ok) return {true, TokenSource::Query};
  if (cookie_ok) return {true, TokenSource::Cookie};
  return {};
}

std::string token_cookie(std::string_view token) {
  return "vnr_token=" + std::string(token) + "; Path=/; HttpOnly; SameSite=Strict";
}

}  // namespace vnr::view
