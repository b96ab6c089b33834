#pragma once
// Untrusted JSON (plan files, control requests, calibration results) parsed without ever recursing on the
// input's structure: nlohmann's parser is iterative, but its serializer and some readers recurse, so a
// document nested 200,000 levels deep must be refused while it is being parsed (issue 16, defect 3).
#include <istream>
#include <stdexcept>
#include <string>

#include <nlohmann/json.hpp>

namespace scancell {

/// What was wrong with the text, never quoting it (a client's file or request is not echoed back).
struct JsonInputError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct JsonLimits {
  int max_depth = 32;         ///< objects and arrays nested deeper are refused
  bool refuse_duplicate_keys = true;  ///< a key given twice in one object (the last would win silently)
};

/// Parses `text`, refusing nesting deeper than `limits.max_depth`, duplicate keys, malformed text and numbers
/// out of range (1e400). Throws JsonInputError naming the byte or the key.
nlohmann::json parse_json_input(const std::string& text, const JsonLimits& limits = {});
nlohmann::json parse_json_input(std::istream& in, const JsonLimits& limits = {});

}  // namespace scancell
