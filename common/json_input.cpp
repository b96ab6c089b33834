#include "common/json_input.hpp"

#include <set>
#include <vector>

namespace scancell {
namespace {

using json = nlohmann::json;

template <class Input>
json parse_bounded(Input&& in, const JsonLimits& limits) {
  std::vector<std::set<std::string>> keys;
  const json::parser_callback_t check = [&](int depth, json::parse_event_t event, json& parsed) {
    if (depth > limits.max_depth)
      throw JsonInputError("nested deeper than " + std::to_string(limits.max_depth) + " levels");
    if (!limits.refuse_duplicate_keys) return true;
    if (event == json::parse_event_t::object_start) keys.emplace_back();
    else if (event == json::parse_event_t::object_end && !keys.empty()) keys.pop_back();
    else if (event == json::parse_event_t::key && !keys.empty() && !keys.back().insert(parsed.get<std::string>()).second)
      throw JsonInputError("key '" + parsed.get<std::string>().substr(0, 64) + "' given twice in one object");
    return true;
  };
  try {
    return json::parse(std::forward<Input>(in), check);
  } catch (const json::parse_error& e) {
    throw JsonInputError("malformed JSON at byte " + std::to_string(e.byte));
  } catch (const json::out_of_range&) {
    throw JsonInputError("a number is out of range");  // e.g. 1e400
  } catch (const json::exception& e) {
    throw JsonInputError("malformed JSON (error " + std::to_string(e.id) + ")");
  }
}

}  // namespace

json parse_json_input(const std::string& text, const JsonLimits& limits) { return parse_bounded(text, limits); }
json parse_json_input(std::istream& in, const JsonLimits& limits) { return parse_bounded(in, limits); }

}  // namespace scancell
