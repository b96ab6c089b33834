// Range images (the PLY the daemon stores per view and reads back): every bad one ends in DataError.
#include <string>

#include "fuzz/fuzz.hpp"
#include "common/errors.hpp"
#include "planner/scan/range_image.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    scancell::planner::range_image_from_ply(std::string(reinterpret_cast<const char*>(data), size), "fuzz.ply");
  } catch (const scancell::DataError&) {
  }
  return 0;
}
