#pragma once
namespace vnr {
// The library's version ("0.1.0"), as the CLI's --version prints it.
const char* version();
}  // namespace vnr
