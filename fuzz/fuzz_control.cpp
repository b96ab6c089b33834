// Control requests (one line of the daemon's socket): every bad one is refused with std::invalid_argument.
#include <string>

#include "daemon/control.hpp"
#include "fuzz/fuzz.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    scancell::daemon::parse_request(std::string(reinterpret_cast<const char*>(data), size));
  } catch (const std::invalid_argument&) {
  }
  return 0;
}
