// Every YAML loader: the first byte picks sensor, spec, planner settings, cell, drivers or calibration
// result; the rest is the file. Every bad file ends in ConfigError naming the key.
#include "calibration/results.hpp"
#include "drivers/config.hpp"
#include "fuzz/fuzz.hpp"
#include "planner/kinematics/cell.hpp"
#include "planner/config.hpp"
#include "common/errors.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const auto path = scancell::fuzz::as_file("config.yaml", data + 1, size - 1);
  namespace sp = scancell::planner;
  try {
    switch (data[0] % 6) {
      case 0: sp::load_sensor(path); break;
      case 1: sp::load_spec(path); break;
      case 2: sp::load_planner_settings(path); break;
      case 3: sp::load_cell(path); break;
      case 4: scancell::drivers::load_driver_setup(path); break;
      case 5: scancell::calibration::load_calibration(path); break;
    }
  } catch (const scancell::ConfigError&) {
  }
  return 0;
}
