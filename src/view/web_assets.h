#pragma once
// The web page's files, embedded at build time from src/view/web/ (cmake/embed_web.cmake): the server
// serves these and nothing else.
#include <cstddef>
#include <string_view>
#include <vector>

namespace vnr::view {

struct WebAsset {
  const char* path;          // "/index.html"
  const char* content_type;  // "text/html; charset=utf-8"
  const unsigned char* data;
  size_t size;
  std::string_view bytes() const { return {reinterpret_cast<const char*>(data), size}; }
};

const std::vector<WebAsset>& web_assets();
// The asset for a request path ("/" is "/index.html"); null when there is none.
const WebAsset* find_web_asset(std::string_view path);

}  // namespace vnr::view
