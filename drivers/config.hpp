#pragma once
// Which driver each cell axis uses, and the trigger and interlock lines (config/drivers/*.yaml). Counts and
// scaling live here, units in every key; errors name the file and key path (scancell::ConfigError).
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <variant>

#include "drivers/canopen_axis.hpp"
#include "drivers/modbus_axis.hpp"

namespace scancell::drivers {

struct CanOpenAxisConfig {
  std::string interface;  // SocketCAN interface (can0 ...)
  CanOpenConfig axis;
};

struct SimAxisConfig {};  // served by scancell-sim's in-process drive (the demo)

struct LineConfig {
  std::string chip;       // gpiochipN or its label (libgpiod lookup)
  unsigned offset = 0;
  bool active_high = true;
};

struct DriverSetup {
  std::map<std::string, std::variant<ModbusConfig, CanOpenAxisConfig, SimAxisConfig>> axes;
  std::optional<LineConfig> trigger, estop, door;
};

DriverSetup load_driver_setup(const std::filesystem::path& file);

}  // namespace scancell::drivers
