#pragma once
// Typed reads of tiny-cuda-nn JSON keys with the config's error messages ("<where>: '<key>' must be
// ..."), shared by the config parser and the encoding files.
#include <cmath>
#include <set>
#include <string>
#include <type_traits>
#include "vnr/error.h"
#include "vnr/json.h"

namespace vnr {

template <typename T>
inline T json_get(const Json& j, const char* key, T dflt, const char* where) {
  if (!j.contains(key)) return dflt;
  const Json& v = j.at(key);
  if constexpr (std::is_same_v<T, bool>) {
    if (!v.is_boolean()) fail("{}: '{}' must be true or false", where, key);
    return v.get<bool>();
  } else if constexpr (std::is_same_v<T, std::string>) {
    if (!v.is_string()) fail("{}: '{}' must be a string", where, key);
    return v.get<std::string>();
  } else if constexpr (std::is_floating_point_v<T>) {
    if (!v.is_number()) fail("{}: '{}' must be a number", where, key);
    return T(v.get<double>());
  } else {
    if (!v.is_number()) fail("{}: '{}' must be a number", where, key);
    double d = v.get<double>();
    if (d < 0 || d != std::floor(d) || d > 4294967295.0)
      fail("{}: '{}' must be a non-negative integer, got {}", where, key, v.dump());
    return T(d);
  }
}

// Fails on a key of the object j that is not in `known`, with the allowed list (settings objects read
// from JSON refuse what they do not know rather than ignore a misspelt key).
inline void json_check_keys(const Json& j, const std::set<std::string>& known, const char* where) {
  if (!j.is_object()) fail("{} must be a JSON object, got {}", where, j.dump());
  for (const auto& [key, value] : j.items()) {
    if (known.count(key)) continue;
    std::string allowed;
    for (const auto& k : known) allowed += (allowed.empty() ? "" : ", ") + k;
    fail("{}: unknown key '{}' (allowed: {})", where, key, allowed);
  }
}

}  // namespace vnr
