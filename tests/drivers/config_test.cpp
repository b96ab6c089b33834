// The real drivers without the simulation or the planner: this executable links scancell_drivers alone (with
// the common library), so a driver that reaches back into planner code fails to link here. The driver setup
// file's keys are checked with their key paths.
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <map>
#include <regex>
#include <sstream>
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

/// docs/drivers.md's key table: every row with one key and a numeric range ("default, [lo, hi]",
/// "required, (lo, hi]") is the range the loader applies (issue 17: a range documented once and checked
/// here): each bound accepted or refused as its bracket says, a step beyond it refused with the key path, and
/// the documented default accepted.
TEST(DriverConfig, TheDocumentedRangesAreTheLoadersRanges) {
  std::ifstream in(std::string(SCANCELL_SOURCE_DIR) + "/docs/drivers.md");
  std::string line;
  bool table = false;
  const std::regex row(R"(^\| `axes\.<axis>\.([a-z_]+)` \| ([a-z_, ]+) \| ([0-9.]+|required), ([\[(])([-0-9.e]+), ([-0-9.e]+)([\])]) \|)");
  // The smallest setup each bus accepts, on axis `lift`; the key under test is appended.
  const std::map<std::string, std::string> base{
      {"modbus_tcp", "driver: modbus_tcp, host: h, port: 502, unit_id: 1, counts_per_mm: 1, profile_velocity_mm_s: 1"},
      {"modbus_rtu", "driver: modbus_rtu, device: /dev/ttyUSB0, baud: 9600, unit_id: 1, counts_per_mm: 1, profile_velocity_mm_s: 1"},
      {"canopen", "driver: canopen, interface: can0, node_id: 5, counts_per_mm: 1, profile_velocity_mm_s: 1"}};
  const auto dir = std::filesystem::temp_directory_path() / "scancell_driver_ranges";
  std::filesystem::create_directories(dir);
  auto load = [&](const std::string& driver, const std::string& key, const std::string& value) -> std::string {
    std::string fields = base.at(driver);
    // A key the base already sets is replaced, not given twice.
    const std::regex own("(^|, )" + key + ": [^,]*");
    fields = std::regex_replace(fields, own, "");
    if (fields.rfind(", ", 0) == 0) fields = fields.substr(2);
    std::ofstream(dir / "d.yaml") << "axes:\n  lift: {" << fields << ", " << key << ": " << value << "}\n";
    try {
      dr::load_driver_setup(dir / "d.yaml");
      return "";
    } catch (const std::exception& e) {
      return e.what();
    }
  };
  std::size_t rows = 0;
  while (std::getline(in, line)) {
    if (line.rfind("## Configuration (`config/drivers/", 0) == 0) table = true;
    else if (table && line.rfind("## ", 0) == 0) break;
    std::smatch m;
    if (!table || !std::regex_search(line, m, row)) continue;
    const std::string key = m[1], def = m[3], lo = m[5], hi = m[6];
    const bool lo_in = m[4] == "[", hi_in = m[7] == "]";
    std::stringstream drivers(m[2].str());
    for (std::string d; std::getline(drivers, d, ',');) {
      d.erase(0, d.find_first_not_of(' '));
      if (!base.count(d)) continue;
      ++rows;
      const std::string where = d + " " + key;
      const std::string path = "axes.lift." + key;
      if (def != "required") {
        EXPECT_EQ(load(d, key, def), "") << where << ": the documented default " << def;
      }
      const std::string at_lo = load(d, key, lo), at_hi = load(d, key, hi);
      EXPECT_EQ(at_lo.empty(), lo_in) << where << " = " << lo << ": " << at_lo;
      EXPECT_EQ(at_hi.empty(), hi_in) << where << " = " << hi << ": " << at_hi;
      // One step beyond each bound (a unit, or a thousandth of a bound under 1).
      const double l = std::stod(lo), h = std::stod(hi);
      const double step_l = std::abs(l) >= 1.0 ? 1.0 : 1e-3, step_h = std::abs(h) >= 1.0 ? 1.0 : 1e-3;
      std::ostringstream below, above;
      below << std::setprecision(12) << l - step_l;
      above << std::setprecision(12) << h + step_h;
      EXPECT_THAT(load(d, key, below.str()), HasSubstr(path)) << where << " = " << below.str();
      EXPECT_THAT(load(d, key, above.str()), HasSubstr(path)) << where << " = " << above.str();
    }
  }
  std::filesystem::remove_all(dir);
  // response_timeout_ms, retries, reconnect_backoff_ms, reconnect_attempts (two buses each), unit_id (two),
  // sdo_timeout_ms, heartbeat_timeout_ms.
  EXPECT_GE(rows, 10u);
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
