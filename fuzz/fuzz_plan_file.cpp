// Plan files (scancell verify / scan read them): DataError for the structure, ConfigError for the embedded
// sensor and spec; nothing else.
#include "fuzz/fuzz.hpp"
#include "common/errors.hpp"
#include "planner/plan_file.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = scancell::fuzz::as_file("plan.json", data, size);
  try {
    scancell::planner::load_plan_file(path);
  } catch (const scancell::DataError&) {
  } catch (const scancell::ConfigError&) {
  }
  return 0;
}
