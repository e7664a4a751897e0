#pragma once
#include <nlohmann/json.hpp>
#include <string>

namespace vnr {

using Json = nlohmann::json;

// Parses JSON that may contain // and /* */ comments (instantvnr and tcnn files do).
// `what` names the source in error messages.
Json parse_json_text(const std::string& text, const std::string& what);
Json parse_json_file(const std::string& path);

// Case-insensitive string equality (tcnn compares "otype" case-insensitively).
bool iequals(const std::string& a, const std::string& b);
std::string to_lower(std::string s);
// A settings key as the command line spells it (max_rel_error: --max-rel-error): how the CLI names the
// setting in the library's messages.
std::string option_name_of(const std::string& key);

}  // namespace vnr
