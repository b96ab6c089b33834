// The real drivers without the simulation or the planner: this executable links scancell_drivers alone (with
// the common library), so a driver that reaches back into planner code fails to link here. The driver setup
// file's keys are checked with their key paths.
#include <filesystem>
#include <fstream>
#include <variant>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "drivers/config.hpp"
#include "drivers/genicam/genicam_scanner.hpp"
#include "drivers/modbus_axis.hpp"

namespace dr = scancell::drivers;
using ::testing::HasSubstr;

TEST(DriverConfig, ShippedSetupLoadsAndMistakesNameTheKey) {
  const auto d = dr::load_driver_setup(std::string(SCANCELL_SOURCE_DIR) + "/config/drivers/turntable-lift-tilt.yaml");
  ASSERT_EQ(d.axes.size(), 5u);
  const auto& reach = std::get<dr::ModbusConfig>(d.axes.at("reach"));
  EXPECT_EQ(reach.unit_id, 1);
  EXPECT_DOUBLE_EQ(reach.counts_per_unit, 1000.0);
  EXPECT_EQ(std::get<dr::ModbusConfig>(d.axes.at("sweep")).parity, 'E');
  EXPECT_EQ(std::get<dr::CanOpenAxisConfig>(d.axes.at("turntable")).axis.node_id, 5);
  ASSERT_TRUE(d.estop.has_value());
  EXPECT_FALSE(d.estop->active_high);
  const auto dir = std::filesystem::temp_directory_path() / "scancell_driver_config";
  std::filesystem::create_directories(dir);
  auto refused = [&](const std::string& text, const std::string& expect) {
    std::ofstream(dir / "d.yaml") << text;
    try {
      dr::load_driver_setup(dir / "d.yaml");
      ADD_FAILURE() << "accepted: " << expect;
    } catch (const std::exception& e) {
      EXPECT_THAT(e.what(), HasSubstr(expect));
    }
  };
  refused("axes:\n  lift: {driver: modbus_tcp, host: h, port: 70000, unit_id: 1, counts_per_mm: 1, profile_velocity_mm_s: 1}\n",
          "axes.lift.port: must be in [1, 65535]");
  refused("axes:\n  lift: {driver: modbus_tcp, host: h, port: 502, unit_id: 1, counts_per_mm: 1, counts_per_rad: 1, profile_velocity_mm_s: 1}\n",
          "give counts_per_mm (linear) or counts_per_rad (rotary)");
  refused("axes:\n  lift: {driver: profibus}\n", "axes.lift.driver: must be modbus_tcp, modbus_rtu, canopen or sim");
  refused("axes:\n  sweep: {driver: modbus_rtu, device: /dev/ttyUSB0, baud: 0, unit_id: 3, counts_per_mm: 1, profile_velocity_mm_s: 1}\n",
          "axes.sweep.baud: must be in [300, 4000000], got 0");
  refused("axes:\n  lift: {driver: sim, speed: 3}\n", "axes.lift.speed: unknown key");
  // A timeout of 0 would be no time at all, not no limit; over ten minutes is a typo.
  const std::string tcp = "axes:\n  lift: {driver: modbus_tcp, host: h, port: 502, unit_id: 1, counts_per_mm: 1, profile_velocity_mm_s: 1, ";
  refused(tcp + "response_timeout_ms: 0}\n", "axes.lift.response_timeout_ms: must be in (0, 600000], got 0");
  refused(tcp + "response_timeout_ms: 900000}\n", "axes.lift.response_timeout_ms: must be in (0, 600000], got 900000");
  std::ofstream(dir / "d.yaml") << tcp + "response_timeout_ms: 0.4}\n";
  EXPECT_EQ(std::get<dr::ModbusConfig>(dr::load_driver_setup(dir / "d.yaml").axes.at("lift")).response_timeout.count(), 1);
  std::filesystem::remove_all(dir);
}

// The real drivers' own code paths, reached without a simulator (and linking their objects without the planner).
TEST(RealDrivers, AModbusAxisWithNoPeerIsAConnectionErrorNamingTheAxisAndAddress) {
  dr::ModbusConfig c;
  c.name = "lift";
  c.host = "127.0.0.1";
  c.port = 1;  // nothing listens on tcpmux here: refused at once
  try {
    dr::ModbusAxis axis(c);
    ADD_FAILURE() << "connected to 127.0.0.1:1";
  } catch (const dr::DriverError& e) {
    EXPECT_EQ(e.kind, dr::DriverError::Kind::connection);
    EXPECT_THAT(e.what(), HasSubstr("lift"));
    EXPECT_THAT(e.what(), HasSubstr("127.0.0.1:1"));
  }
}

TEST(RealDrivers, AGenicamScannerRefusesASensorModelThatIsNotALineScanner) {
  scancell::planner::SensorModel sensor;
  sensor.kind = scancell::planner::SensorKind::random_access;
  dr::GenicamConfig c;
  c.device = "127.0.0.1";
  try {
    dr::GenicamScanner scanner(sensor, c);
    ADD_FAILURE() << "accepted a random_access sensor model";
  } catch (const dr::DriverError& e) {
    EXPECT_EQ(e.kind, dr::DriverError::Kind::refused);
    EXPECT_THAT(e.what(), HasSubstr("line_scan sensor model"));
  }
}
