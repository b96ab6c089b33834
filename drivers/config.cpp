#include "drivers/config.hpp"

#include <algorithm>
#include <cmath>

#include "common/yaml_section.hpp"

namespace scancell::drivers {
namespace {

using scancell::Section;

std::chrono::milliseconds ms(Section& s, const std::string& key, std::chrono::milliseconds fallback) {
  // (0, 10 min]; a fraction of a millisecond is one, never a zero timeout.
  const double v = s.positive_up_to(key, static_cast<double>(fallback.count()), 600000.0);
  return std::chrono::milliseconds(std::max(1L, std::lround(v)));
}

/// Counts per unit and profile velocity: per mm for linear axes, per rad for rotary ones; exactly one.
void scaling(Section& s, double& counts, double& velocity) {
  const bool mm = s.has("counts_per_mm"), rad = s.has("counts_per_rad");
  if (mm == rad) s.fail(s.key_path("counts_per_mm"), "give counts_per_mm (linear) or counts_per_rad (rotary), one of them");
  counts = s.positive(mm ? "counts_per_mm" : "counts_per_rad");
  velocity = s.positive(mm ? "profile_velocity_mm_s" : "profile_velocity_rad_s");
  if (!(counts <= 1e7)) s.fail(s.key_path(mm ? "counts_per_mm" : "counts_per_rad"), "must be at most 1e7");
  // The drive's velocity register is 32-bit signed (checked again on every move).
  if (!(velocity * counts < 2147483647.0))
    s.fail(s.key_path(mm ? "profile_velocity_mm_s" : "profile_velocity_rad_s"),
           "times the counts per unit exceeds the drive's 32-bit velocity register");
}

LineConfig line(Section s) {
  LineConfig l;
  l.chip = s.get<std::string>("chip");
  const int off = s.get<int>("offset");
  if (off < 0 || off > 1023) s.fail(s.key_path("offset"), "must be in [0, 1023]");
  l.offset = static_cast<unsigned>(off);
  l.active_high = s.get_or<bool>("active_high", true);
  s.finish();
  return l;
}

}  // namespace

DriverSetup load_driver_setup(const std::filesystem::path& file) {
  YAML::Node root;
  Section y = scancell::open_root(file, root);
  DriverSetup d;
  Section axes = y.section("axes");
  for (const auto& name : axes.keys()) {
    Section a = axes.section(name);
    const std::string kind = a.get<std::string>("driver");
    if (kind == "modbus_tcp" || kind == "modbus_rtu") {
      ModbusConfig c;
      c.name = name;
      if (kind == "modbus_tcp") {
        c.transport = ModbusConfig::Transport::tcp;
        c.host = a.get<std::string>("host");
        c.port = a.get<int>("port");
        if (c.port < 1 || c.port > 65535) a.fail(a.key_path("port"), "must be in [1, 65535]");
      } else {
        c.transport = ModbusConfig::Transport::rtu;
        c.device = a.get<std::string>("device");
        c.baud = a.get<int>("baud");
        if (c.baud < 300 || c.baud > 4000000) a.fail(a.key_path("baud"), "must be in [300, 4000000], got " + std::to_string(c.baud));
        const std::string parity = a.get_or<std::string>("parity", "N");
        if (parity != "N" && parity != "E" && parity != "O") a.fail(a.key_path("parity"), "must be N, E or O");
        c.parity = parity[0];
      }
      c.unit_id = a.get<int>("unit_id");
      if (c.unit_id < 1 || c.unit_id > 247) a.fail(a.key_path("unit_id"), "must be in [1, 247]");
      scaling(a, c.counts_per_unit, c.profile_velocity);
      c.response_timeout = ms(a, "response_timeout_ms", c.response_timeout);
      c.retries = a.ranged<int>("retries", c.retries, 0, 20);
      c.reconnect_backoff = ms(a, "reconnect_backoff_ms", c.reconnect_backoff);
      c.reconnect_attempts = a.ranged<int>("reconnect_attempts", c.reconnect_attempts, 1, 10);
      a.finish();
      d.axes[name] = c;
    } else if (kind == "canopen") {
      CanOpenAxisConfig c;
      c.interface = a.get<std::string>("interface");
      c.axis.name = name;
      c.axis.node_id = a.get<int>("node_id");
      if (c.axis.node_id < 1 || c.axis.node_id > 127) a.fail(a.key_path("node_id"), "must be in [1, 127]");
      scaling(a, c.axis.counts_per_unit, c.axis.profile_velocity);
      c.axis.sdo_timeout = ms(a, "sdo_timeout_ms", c.axis.sdo_timeout);
      c.axis.heartbeat_timeout = ms(a, "heartbeat_timeout_ms", c.axis.heartbeat_timeout);
      a.finish();
      d.axes[name] = c;
    } else if (kind == "sim") {
      a.finish();
      d.axes[name] = SimAxisConfig{};
    } else {
      a.fail(a.key_path("driver"), "must be modbus_tcp, modbus_rtu, canopen or sim, got '" + kind + "'");
    }
  }
  if (y.has("trigger")) d.trigger = line(y.section("trigger"));
  if (y.has("interlocks")) {
    Section i = y.section("interlocks");
    if (i.has("estop")) d.estop = line(i.section("estop"));
    if (i.has("door")) d.door = line(i.section("door"));
    i.finish();
  }
  y.finish();
  return d;
}

}  // namespace scancell::drivers
