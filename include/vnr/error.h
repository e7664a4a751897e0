#pragma once
#include <fmt/format.h>
#include <stdexcept>
#include <string>

namespace vnr {

// The one exception type of the library. Its message is a single line meant for the user;
// the CLI prints it as "vnr: error: <message>" and exits non-zero.
class Error : public std::runtime_error {
public:
  explicit Error(const std::string& msg) : std::runtime_error(msg) {}
};

template <typename... Args>
[[noreturn]] void fail(fmt::format_string<Args...> f, Args&&... args) {
  throw Error(fmt::format(f, std::forward<Args>(args)...));
}

}  // namespace vnr
